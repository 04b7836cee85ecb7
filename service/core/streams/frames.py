"""Batch state frames without a full snapshot: packed where the engine is, serialised off-loop.

A subscriber of many worlds used to cost a full snapshot (every field of every world copied to
the host) plus, on the event loop, cutting and serialising it. Now the sim thread asks the
engine for the rows of exactly the subscribed worlds (`pack_rows`: a kernel and one pinned copy
on a GPU, a few vectorised gathers on the CPU) and hands them to `FrameSender`, a thread of its
own that waits for the copy with the GIL released, builds the frame bytes and passes them to
the event loop, which only sends. The bytes are exactly those of `service.wire.batch_frame` and
`batch_frame_binary` for the same tick (tests/test_frames.py holds them to it).

Large JSON frames are serialised in a helper process (from BIG_JSON_ROWS worlds), smaller ones
in slices of rows letting the GIL go between slices: the sim thread is never held up for
longer than one slice.
"""

from __future__ import annotations

import concurrent.futures
import logging
import multiprocessing
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.core.sim.batch import Batch, PacksFrames
from service.core.sim.pace import prompt_gil
from service.core.sim.packed_rows import PackedRows
from service.core.sim.types import EntityFrame, Snapshot
from service.core.streams import wire
from service.core.streams.formats import BINARY, BINARY_ENTITIES, JSON, JSON_ENTITIES

log = logging.getLogger("armfleet.frames")

# From this many worlds a JSON frame is serialised in a helper process (spawned at the first
# one): tens of ms of orjson per frame would otherwise hold the GIL against the sim thread.
BIG_JSON_ROWS = 4096
JSON_PROCESSES = 2  # helpers, so that one frame is serialised while the next is
JSON_SLICE = 2048  # rows serialised per GIL hold in a JSON frame (~3 ms of orjson on a GPU host)
_NOOP: Callable[[], None] = lambda: None  # noqa: E731


@dataclass
class FrameData:
    """One tick's frame for one world selection: the rows, and for JSON the host columns that
    JSON reports at full precision (sim_time and target as float64, faults as integers)."""

    packed: PackedRows
    sim_time: np.ndarray | None = None
    target: np.ndarray | None = None
    faults: np.ndarray | None = None
    extra: dict[str, Any] | None = None  # JSON's last fields (None: json_extra)
    entities: EntityFrame | None = None  # read when a subscriber asked (JSON_ENTITIES)
    safety: np.ndarray | None = None  # the worlds' safety modes at the tick (None: NORMAL)

    @property
    def tick(self) -> int:
        return self.packed.tick

    @property
    def ids(self) -> np.ndarray:
        return self.packed.ids


def rows_of(snap: Snapshot, ids: np.ndarray) -> np.ndarray:
    """The binary frame's rows of `ids` cut from a snapshot (engines without `pack_rows`)."""
    cols = (snap.sim_time[ids, None], snap.position[ids], snap.velocity[ids], snap.effort[ids])
    rest = (snap.target[ids], snap.flange_pos[ids], snap.flange_quat[ids], snap.faults[ids, None])
    return np.concatenate((*cols, *rest), axis=1, dtype="<f4")


def pack(batch: Batch, ids: np.ndarray, json: bool) -> FrameData | None:
    """Rows of worlds `ids` at the batch's last tick (sim thread, between ticks).

    Engines that `PacksFrames` (warp, native) gather on their side; others are cut from a
    snapshot. `json` adds the host columns. None when the engine has no buffer free for this
    selection (its frames are still being sent): the frame is skipped, the tick goes on.
    """
    if not _packs_frames(batch):
        snap = batch.snapshot()
        data = FrameData(PackedRows(snap.tick, ids, rows_of(snap, ids)))
        data.safety = None if snap.safety is None else snap.safety[ids]
        if json:
            data.sim_time, data.target, data.faults = (
                snap.sim_time[ids],
                snap.target[ids],
                snap.faults[ids],
            )
        return data
    packed = batch.pack_rows(ids)
    if packed is None:
        return None
    data = FrameData(packed)
    if json:
        host = packed.host if packed.host is not None else batch.host_columns(ids)
        data.sim_time, data.target, data.faults = host
    return data


_PACKS_FRAMES: dict[type, bool] = {}


def _packs_frames(batch: Batch) -> bool:
    """isinstance(batch, PacksFrames), once per engine class: a runtime protocol check looks
    up every member each time (~10 us, each frame on the sim thread)."""
    kind = type(batch)
    known = _PACKS_FRAMES.get(kind)
    if known is None:
        known = _PACKS_FRAMES[kind] = isinstance(batch, PacksFrames)
    return known


# -- serialising -------------------------------------------------------------------------------


def binary(data: FrameData, rows: np.ndarray, names: list[str]) -> bytes:
    """`wire.batch_frame_binary`'s bytes from packed rows (one copy of them, `_joined`)."""
    header = wire.dumps(wire.binary_header(data.tick, len(data.ids), names))
    ids = data.ids.astype("<i4").tobytes()
    size = len(header).to_bytes(4, "little")
    tail = wire.safety_block(data.safety, len(data.ids))
    return _joined(b"".join((wire.BINARY_MAGIC, size, header, ids)), rows, tail)


def _joined(head: bytes, rows: np.ndarray, tail: bytes) -> bytes:
    """`head`, the rows' float32 bytes, then `tail`, in one buffer (a bytearray, sent as
    bytes are). numpy copies the rows and lets the GIL go meanwhile: a bytes join held it for
    the whole copy (~1 ms for 65,536 worlds), on this thread just as the sim thread, whose
    tick this frame was packed at, goes on to launch the next."""
    rows = np.ascontiguousarray(rows, dtype="<f4")
    end = len(head) + rows.nbytes
    out = bytearray(end + len(tail))
    out[: len(head)] = head
    np.frombuffer(out, np.uint8, rows.nbytes, len(head))[:] = rows.reshape(-1).view(np.uint8)
    out[end:] = tail
    return out  # type: ignore[return-value]  # bytes-like: every consumer takes a bytearray


def binary_entities(data: FrameData, rows: np.ndarray, names: list[str]) -> bytes:
    """`wire.batch_frame_binary(..., entities=True)`'s bytes: the rows, then the entities."""
    assert data.entities is not None
    header = wire.dumps(wire.binary_header(data.tick, len(data.ids), names, data.entities))
    ids = data.ids.astype("<i4").tobytes()
    size = len(header).to_bytes(4, "little")
    block = wire.entity_block(data.entities)
    tail = wire.safety_block(data.safety, len(data.ids))
    return b"".join((wire.BINARY_MAGIC, size, header, ids, memoryview(rows), block, tail))


def _array(values: np.ndarray, sliced: bool) -> bytes:
    """orjson's text of a numpy array; `sliced`: a slice of rows at a time (see module doc)."""
    if not sliced or len(values) <= JSON_SLICE:
        return wire.dumps(np.ascontiguousarray(values))
    parts = []
    for lo in range(0, len(values), JSON_SLICE):
        parts.append(wire.dumps(np.ascontiguousarray(values[lo : lo + JSON_SLICE]))[1:-1])
        time.sleep(0)  # lets the sim thread take the GIL between slices
    return b"[" + b",".join(parts) + b"]"


# The columns of a JSON frame that commands, faults or a new selection change, and ticks do not:
# from one frame to the next they are usually the same numbers, whose text is kept here.
_STEADY_TEXT: dict[tuple[str, str, tuple[int, ...]], tuple[bytes, bytes]] = {}
_STEADY_KEYS = 48  # columns of 16 selection sizes at most; then it starts again


def _steady_array(name: str, values: np.ndarray, sliced: bool) -> bytes:
    """`_array`'s text of `values`, a column that seldom changes between frames: the text of
    the last frame's when its bytes are the same (orjson writes the same array the same way;
    ~80 us of orjson for 500 worlds' float64 targets against a 28 KB compare). The frame
    thread and each helper process keep their own."""
    key = (name, values.dtype.str, values.shape)
    raw = values.tobytes()
    last = _STEADY_TEXT.get(key)
    if last is not None and last[0] == raw:
        return last[1]
    text = _array(values, sliced)
    if last is None and len(_STEADY_TEXT) >= _STEADY_KEYS:  # sockets of many sizes came and went
        _STEADY_TEXT.clear()
    _STEADY_TEXT[key] = (raw, text)
    return text


def json_extra(nworld: int) -> dict[str, Any]:
    """What `wire.batch_frame` ends with for `nworld` worlds in their usual state: each world's
    safety mode NORMAL, no trajectory running (the hub fills in what it knows)."""
    return {"safety_mode": ["NORMAL"] * nworld, "trajectories": {}}


_JSON_COLUMNS = (
    ("position", slice(1, 8)),
    ("velocity", slice(8, 15)),
    ("effort", slice(15, 22)),
    ("target", None),
    ("flange_position", slice(29, 32)),
    ("flange_quaternion", slice(32, 36)),
)


def json_bytes(
    tick: int,
    names: list[str],
    ids: np.ndarray,
    sim_time: np.ndarray,
    rows: np.ndarray,
    target: np.ndarray,
    faults: np.ndarray,
    sliced: bool = True,
    extra: dict[str, Any] | None = None,
) -> bytes:
    """`wire.batch_frame`'s bytes from packed rows plus the host columns (a module function:
    the helper process runs it too)."""
    head = wire.dumps({"op": "states", "tick": tick, "name": names})[:-1]
    parts = [head, b',"worlds":', _steady_array("worlds", ids, sliced)]
    parts += [b',"sim_time":', _array(sim_time, sliced)]
    for name, cols in _JSON_COLUMNS:
        if cols is None:
            text = _steady_array(name, target, sliced)
        else:
            text = _array(rows[:, cols], sliced)
        parts += [b',"', name.encode(), b'":', text]
    parts += [b',"faults":', _steady_array("faults", faults, sliced)]
    for name, value in (json_extra(len(ids)) if extra is None else extra).items():
        parts += [b',"', name.encode(), b'":', wire.dumps(value)]
    return b"".join((*parts, b"}"))


def json(data: FrameData, rows: np.ndarray, names: list[str]) -> bytes:
    """`wire.batch_frame`'s bytes from packed rows, serialised on this thread."""
    assert data.sim_time is not None and data.target is not None and data.faults is not None
    return json_bytes(
        data.tick, names, data.ids, data.sim_time, rows, data.target, data.faults, True, data.extra
    )


def json_entities(data: FrameData, rows: np.ndarray, names: list[str]) -> bytes:
    """`wire.batch_frame(..., entities=True)`'s bytes: the JSON frame, then `entities`."""
    assert data.sim_time is not None and data.target is not None and data.faults is not None
    assert data.entities is not None
    extra = {**(json_extra(len(data.ids)) if data.extra is None else data.extra)}
    extra["entities"] = wire.entity_columns(data.entities)
    return json_bytes(
        data.tick, names, data.ids, data.sim_time, rows, data.target, data.faults, True, extra
    )


ENCODERS: dict[str, Callable[[FrameData, np.ndarray, list[str]], bytes]] = {
    BINARY: binary,
    JSON: json,
    JSON_ENTITIES: json_entities,
    BINARY_ENTITIES: binary_entities,
}


# -- the sender thread -------------------------------------------------------------------------


@dataclass
class Job:
    """Frames of one tick and selection to serialise in `formats`, for `targets` to deliver."""

    data: FrameData
    formats: Sequence[str]
    targets: Any  # passed back to `deliver` untouched (the subscriptions that asked)
    names: list[str]  # the joint names the frames carry
    # the worlds' ids as bytes (the hub's, hashed once); None: made from the ids, which costs
    # ~0.5 ms of the sim thread a frame at 65,536 worlds
    selection: bytes | None = None


class FrameSender:
    """Serialises packed frames on a thread of its own and hands the bytes to `deliver`.

    At most one job per selection waits: a newer one replaces it (its buffer released), so a
    slow consumer costs frames, never memory or the sim thread's time.
    """

    def __init__(self, deliver: Callable[[Job, dict[str, bytes]], None]) -> None:
        self._deliver = deliver
        prompt_gil()  # the sim thread gets the GIL back between two slices (core/sim/pace.py)
        self._cv = threading.Condition()
        self._jobs: dict[bytes, Job] = {}
        self._running = True
        self.replaced = 0  # jobs dropped for a newer one of the same selection (metrics)
        self._pool: concurrent.futures.ProcessPoolExecutor | None = None
        self._json_in_flight = 0  # big JSON frames in the helpers (this thread and callbacks)
        self._thread = threading.Thread(target=self._run, name="armfleet-frames", daemon=True)
        self._thread.start()

    def _in_process(self, job: Job, rows: np.ndarray) -> list[str]:
        """Hand a big frame's JSON formats to the helper processes (several frames in flight,
        delivered when done, in order of completion); the formats handed (or dropped because
        every helper is busy), none when the frame is serialised here instead."""
        asked = [f for f in job.formats if f in (JSON, JSON_ENTITIES)]
        if not asked or len(job.data.ids) < BIG_JSON_ROWS:
            return []
        if self._pool is None:
            ctx = multiprocessing.get_context("spawn")  # never fork a process holding CUDA
            self._pool = concurrent.futures.ProcessPoolExecutor(JSON_PROCESSES, mp_context=ctx)
        d = job.data
        rows = np.array(rows)  # a copy: the pinned buffer goes back to the engine at once
        for f in asked:
            if self._json_in_flight >= JSON_PROCESSES:
                self.replaced += 1  # all helpers busy: dropped (the next frame is newer)
                continue
            extra = d.extra
            if f == JSON_ENTITIES and d.entities is not None:
                extra = {**(json_extra(len(d.ids)) if extra is None else extra)}
                extra["entities"] = wire.entity_columns(d.entities)
            args = (d.tick, job.names, d.ids, d.sim_time, rows, d.target, d.faults, False, extra)
            self._json_in_flight += 1
            fut = self._pool.submit(json_bytes, *args)
            fut.add_done_callback(lambda done, f=f: self._json_done(job, f, done))
        return asked

    def _json_done(self, job: Job, fmt: str, fut: concurrent.futures.Future[bytes]) -> None:
        self._json_in_flight -= 1
        if not fut.cancelled() and fut.exception() is None:
            self._deliver(job, {fmt: fut.result()})

    def submit(self, job: Job) -> None:
        key = job.selection if job.selection is not None else job.data.ids.tobytes()
        with self._cv:
            old = self._jobs.get(key)
            self._jobs[key] = job
            self._cv.notify()
        if old is not None:
            self.replaced += 1
            old.data.packed.release()

    def stop(self) -> None:
        with self._cv:
            self._running = False
            self._cv.notify()
        self._thread.join(timeout=5)
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)

    def _run(self) -> None:
        while True:
            with self._cv:
                while self._running and not self._jobs:
                    self._cv.wait()
                if not self._running:
                    return
                _, job = self._jobs.popitem()
            try:
                rows = job.data.packed.wait()
                handed = self._in_process(job, rows)
                formats = [f for f in job.formats if f not in handed]
                out = {f: ENCODERS[f](job.data, rows, job.names) for f in formats}
            except Exception:
                log.exception("a frame could not be serialised")
                continue
            finally:
                job.data.packed.release()
            if out:
                self._deliver(job, out)
