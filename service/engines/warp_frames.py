"""What a state frame carries, packed where the worlds live: on the GPU for the warp engine.

A WebSocket batch frame is one float32 row per world (`service.wire.BINARY_COLUMNS`). At tens of
thousands of worlds, building those rows on the host from a full snapshot (every field of every
world copied off the device, then cut and concatenated) costs more than the tick itself. Here a
kernel gathers exactly the rows of the subscribed worlds into a device buffer, right after the
tick on the tick's stream; one asynchronous copy on a side stream moves them into pinned host
memory, and whoever serialises the frame waits for that copy, with the GIL released, on its own
thread. The sim thread only launches: the next tick never waits for a frame beyond the copy.

Snapshots (what HTTP reads and the other sinks get) come through pinned buffers too, handed out
as views and reused once nothing holds them, so that a snapshot is one copy and no allocation.
Nothing here is thread-safe on its own: `pack` and `PinnedPool.copy_out` run on the sim thread,
a `PackedRows` is waited on and released by one consumer (service.core.streams.frames.FrameSender).
"""

from __future__ import annotations

import contextlib
import ctypes
import sys
from collections.abc import Callable

import numpy as np
import warp as wp

from service.core.sim.device_turns import DeviceTurns
from service.core.sim.packed_rows import PackedRows

NCOL = 37  # sim_time, position 7, velocity 7, effort 7, target 7, flange xyz, flange wxyz, faults
RING = 3  # frames in flight per world selection (being copied or serialised)
KNOWN = 64  # selections the packer knows by their array (`DevicePacker._ring`)


@wp.kernel(enable_backward=False)
def _pack_rows(
    state: wp.array2d(dtype=float),
    targets: wp.array2d(dtype=float),
    world_ticks: wp.array(dtype=wp.int64),
    faults: wp.array(dtype=wp.int32),
    ids: wp.array(dtype=wp.int32),
    tick_dt: wp.float64,
    out: wp.array2d(dtype=float),
):
    # Row i of the frame is world ids[i], columns as service.wire.BINARY_COLUMNS; sim_time is
    # computed in float64 and rounded once, exactly as the host's ticks * tick_dt -> float32.
    i = wp.tid()
    w = ids[i]
    out[i, 0] = wp.float32(wp.float64(world_ticks[w]) * tick_dt)
    for j in range(21):
        out[i, 1 + j] = state[w, j]  # position, velocity, effort
    for j in range(7):
        out[i, 22 + j] = targets[w, j]  # float32 of the host's float64 targets
    for j in range(7):
        out[i, 29 + j] = state[w, 21 + j]  # flange position, quaternion w x y z
    out[i, 36] = wp.float32(faults[w])


@wp.kernel(enable_backward=False)
def count_tick(world_ticks: wp.array(dtype=wp.int64)):
    """Part of the captured tick: every world's tick counter (for sim_time) advances by one."""
    world_ticks[wp.tid()] += wp.int64(1)


@wp.kernel(enable_backward=False)
def zero_reset_ticks(key: wp.array(dtype=int), world_ticks: wp.array(dtype=wp.int64)):
    """Worlds being reset (key >= 0) start their sim_time again."""
    w = wp.tid()
    if key[w] >= 0:
        world_ticks[w] = wp.int64(0)


class PinnedPool:
    """Pinned host copies of device arrays, handed out as numpy views and reused once no view
    of a buffer is alive (a Snapshot's fields keep theirs busy while any reader holds them).

    Every view numpy makes of a buffer refers to its one flat array (numpy collapses view
    chains to the first array over foreign memory), so that array's reference count says
    whether anything still reads the buffer.
    """

    MAX_PER_SHAPE = 12  # beyond this many live snapshots, plain (pageable) copies are made

    def __init__(self, turns: DeviceTurns | None = None) -> None:
        self._turns = turns  # lent while the copies are waited for (core/sim/device_turns.py)
        self._bufs: dict[tuple[int, ...], list[tuple[wp.array, np.ndarray]]] = {}

    def _take(self, src: wp.array, pinned: bool) -> tuple[wp.array, np.ndarray] | None:
        dtype = np.dtype(wp.dtype_to_numpy(src.dtype))
        ring = self._bufs.setdefault((*src.shape, dtype.num), [])
        for arr, flat in ring:
            if sys.getrefcount(flat) <= _FREE_REFS:
                return arr, flat
        if len(ring) >= self.MAX_PER_SHAPE:
            return None
        arr = wp.empty(src.shape, dtype=src.dtype, device="cpu", pinned=pinned)
        buf = (ctypes.c_byte * (arr.size * dtype.itemsize)).from_address(arr.ptr)
        ring.append((arr, np.frombuffer(buf, dtype=dtype)))
        return ring[-1]

    def copy_out(self, srcs: tuple[wp.array, ...], device: wp.Device) -> list[np.ndarray]:
        """Host copies of device arrays `srcs` as of now, in one sync of the current stream
        only (`array.numpy()` copies on CUDA's legacy stream, which waits for every stream of
        the device: the camera renderer's pictures too)."""
        outs: list[np.ndarray] = []
        for src in srcs:
            got = self._take(src, device.is_cuda)
            if got is None:
                outs.append(src.numpy())  # synchronous, a fresh array
                continue
            arr, flat = got
            wp.copy(arr, src)
            outs.append(flat.reshape(src.shape))
        if device.is_cuda:
            stream = wp.get_stream(device)
            with self._turns.lent() if self._turns else contextlib.nullcontext():
                wp.synchronize_stream(stream)  # ctypes: the GIL is released meanwhile
        return outs


# References to a free buffer's flat array inside the loop above: the ring's tuple, the loop
# variable and getrefcount's argument.
_FREE_REFS = 3


class BesideCopy:
    """Host copies of device arrays made beside the next tick, for a snapshot nobody waits for
    (the loop's periodic one): a device-to-device copy into buffers of its own on the tick's
    stream (tens of microseconds), then the copy into `PinnedPool` buffers on a side stream
    while the next tick runs. `PinnedPool.copy_out` held the tick up for the whole transfer
    (42 MB, ~1.7 ms at 65,536 worlds on an H100, ten times a second) with the device idle.
    On Warp's CPU device the copies are done when `start` returns.
    """

    def __init__(self, device: wp.Device, pool: PinnedPool) -> None:
        """Made with the engine, while its stream is the device's current one."""
        self._device = device
        self._pool = pool
        self._stream = wp.Stream(device) if device.is_cuda else None
        self._tick_stream = wp.get_stream(device) if device.is_cuda else None  # the engine's
        self._staging: dict[tuple[int, ...], wp.array] = {}
        self._done: wp.Event | None = None  # the end of the last copy to the host

    def start(self, srcs: tuple[wp.array, ...]) -> tuple[list[np.ndarray], Callable[[], None]]:
        """The host arrays that will hold `srcs` as of now, and the wait for them (the GIL
        released meanwhile); copies done at once on the CPU or when no pinned buffer is free."""
        if self._stream is None or self._tick_stream is None:
            return self._pool.copy_out(srcs, self._device), _NOOP
        bufs, outs = [], []
        for src in srcs:
            got = self._pool._take(src, True)
            if got is None:
                return self._pool.copy_out(srcs, self._device), _NOOP
            bufs.append(got[0])
            outs.append(got[1].reshape(src.shape))  # a view: the buffer is busy from now on
        tick_stream = self._tick_stream
        if self._done is not None:  # the staging buffers are read until the last copy's end
            tick_stream.wait_event(self._done)
        staged = [self._stage(src) for src in srcs]
        for stage, src in zip(staged, srcs, strict=True):
            wp.copy(stage, src, stream=tick_stream)
        self._stream.wait_event(tick_stream.record_event())
        for buf, stage in zip(bufs, staged, strict=True):
            wp.copy(buf, stage, stream=self._stream)
        done = self._done = self._stream.record_event()
        turns = self._pool._turns

        def wait() -> None:
            with turns.lent() if turns else contextlib.nullcontext():
                wp.synchronize_event(done)  # ctypes: the GIL is released meanwhile

        return outs, wait

    def _stage(self, src: wp.array) -> wp.array:
        key = (*src.shape, np.dtype(wp.dtype_to_numpy(src.dtype)).num)
        stage = self._staging.get(key)
        if stage is None:
            stage = self._staging[key] = wp.empty_like(src)
        return stage


def _noop() -> None:
    """Nothing to wait for."""


_NOOP: Callable[[], None] = _noop


class _Slot:
    def __init__(self, k: int, device: wp.Device) -> None:
        self.ids = wp.empty(k, dtype=wp.int32, device=device)
        self.dev = wp.empty((k, NCOL), dtype=float, device=device)
        self.host = wp.empty((k, NCOL), dtype=float, device="cpu", pinned=device.is_cuda)
        self.rows = self.host.numpy()
        self.copied = wp.Event(device) if device.is_cuda else None
        self.busy = False


class DevicePacker:
    """Packs frame rows of any world selection on the engine's device (see module doc)."""

    def __init__(self, device: wp.Device, tick_dt: float) -> None:
        self.device = device
        self.tick_dt = tick_dt
        self._slots: dict[bytes, list[_Slot]] = {}
        self._known: dict[int, tuple[np.ndarray, list[_Slot]]] = {}  # id(ids) -> (ids, ring)
        self._copy_stream = wp.Stream(device) if device.is_cuda else None

    def pack(
        self,
        tick: int,
        ids: np.ndarray,
        state: wp.array,
        targets: wp.array,
        world_ticks: wp.array,
        faults: wp.array,
    ) -> PackedRows | None:
        """Launch the gather and the copy for `ids` (sorted world ids); None when every slot of
        this selection is still in flight (the frame is skipped, the tick is not held up)."""
        ring = self._ring(ids)
        slot = next((s for s in ring if not s.busy), None)
        if slot is None:
            if len(ring) >= RING:
                return None
            slot = _Slot(len(ids), self.device)
            slot.ids.assign(ids.astype(np.int32))
            ring.append(slot)
        slot.busy = True
        k = len(ids)
        with wp.ScopedDevice(self.device):
            wp.launch(
                _pack_rows,
                dim=k,
                inputs=[state, targets, world_ticks, faults, slot.ids, wp.float64(self.tick_dt)],
                outputs=[slot.dev],
            )
            if self._copy_stream is None:
                wp.copy(slot.host, slot.dev)
                done = None
            else:
                # The side stream copies while the next tick runs on the main stream; the main
                # stream gathers into this slot again only after the copy (the slot's `busy`).
                self._copy_stream.wait_event(wp.get_stream(self.device).record_event())
                wp.copy(slot.host, slot.dev, stream=self._copy_stream)
                done = self._copy_stream.record_event(slot.copied)

        def release(slot: _Slot = slot) -> None:
            slot.busy = False

        return PackedRows(tick, ids, slot.rows, done, release)

    def _ring(self, ids: np.ndarray) -> list[_Slot]:
        """The slots of selection `ids`, by its bytes; a read-only array passed again (the
        hub's subscriptions pass theirs every frame) is known by itself: hashing the bytes of
        65,536 ids cost the sim thread ~0.5 ms a frame."""
        known = self._known.get(id(ids))
        if known is not None and known[0] is ids:
            return known[1]
        ring = self._slots.setdefault(ids.tobytes(), [])
        if not ids.flags.writeable:  # its ids cannot change under the ring's
            if len(self._known) >= KNOWN:
                self._known.clear()
            self._known[id(ids)] = (ids, ring)  # holding `ids`: its id is not reused
        return ring

    def forget(self, ids: np.ndarray) -> None:
        """Drop the buffers of a selection nobody subscribes to any more."""
        self._slots.pop(ids.tobytes(), None)
        self._known = {k: v for k, v in self._known.items() if not np.array_equal(v[0], ids)}
