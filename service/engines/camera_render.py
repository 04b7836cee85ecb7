"""BatchRenderer: MuJoCo Warp's batch renderer drawing given world states, for any engine.

Every engine hands over the asked worlds' qpos (`Renderable.render_state`); this module
copies those rows into a render batch of its own (an mjwarp Model and Data of `slots` worlds
on the engine's device), recomputes the kinematics there and ray-casts the cameras. So the
same state gives the same pixels whichever engine stepped it, the engine's own arrays are
never touched from the render thread, and only the asked worlds and the asked camera are
drawn: one render context per camera, launched over the first k slots only.

Only the k drawn worlds' pixels leave the device, and RGB leaves as RGB: the renderer's packed
0xAARRGGBB words are turned into 3 bytes a pixel by a kernel on the device (`_rgb_bytes`), so
the host gets one contiguous (k, h, w, 3) copy and no strided reordering (on a GPU, reordering
16,384 64x64 images on the host took thirty times longer than drawing them).

Nothing here is thread-safe: one thread (the camera feed's) owns a BatchRenderer.
"""

from __future__ import annotations

import contextlib
import threading
import time
import weakref
from collections.abc import Iterator
from dataclasses import dataclass

import mujoco
import mujoco_warp as mjw
import numpy as np
import warp as wp

from service.core.cameras.catalog import CameraSpec
from service.core.sim.device_turns import DeviceTurns
from service.engines.cuda_streams import render_stream


@dataclass(frozen=True)
class Images:
    """What one camera saw in k worlds; an output the camera does not draw is None.

    rgb: (k, height, width, 3) uint8; depth: (k, height, width) float32, metres along the
    optical axis (planar, as ROS depth images), 0 where the ray hit nothing; seg: (k, height,
    width) int32 geom id, -1 for background.
    """

    rgb: np.ndarray | None
    depth: np.ndarray | None
    seg: np.ndarray | None


@wp.kernel
def _rgb_bytes(packed: wp.array2d(dtype=wp.uint32), out: wp.array2d(dtype=wp.uint8)):
    """Packed 0xAARRGGBB (one word a pixel) to R, G, B bytes, for world i, pixel p."""
    i, p = wp.tid()
    c = packed[i, p]
    out[i, 3 * p] = wp.uint8((c >> wp.uint32(16)) & wp.uint32(255))
    out[i, 3 * p + 1] = wp.uint8((c >> wp.uint32(8)) & wp.uint32(255))
    out[i, 3 * p + 2] = wp.uint8(c & wp.uint32(255))


class _HostBuffers:
    """Pinned host buffers that pictures borrow their pixels from, for one device array.

    Out of a CUDA device, a copy into pinned memory runs at the bus's speed (201 MB in about
    8 ms on an H100's PCIe 5), into fresh pageable memory at half that or less. A picture's
    arrays are views of a borrowed buffer, which comes back when the last view of it is gone
    (a weakref finalizer: the senders of every socket of the picture are done with it). At
    most `keep` buffers are made; while all are lent, a picture gets a pageable copy of its
    own, so a slow reader never holds drawing back here."""

    def __init__(self, like: wp.array, keep: int = 8) -> None:
        self._like = like
        self._keep = keep
        self._free: list[wp.array] = []
        self._made = 0
        self._lock = threading.Lock()

    def copy(self, k: int) -> np.ndarray:
        """The first k rows of the device array, in a host array of their own (waits)."""
        view = self._like[:k]
        buf = self.borrow()
        if buf is None:
            return view.numpy()
        wp.copy(buf, view, count=view.size)
        wp.synchronize_stream(self._like.device.stream)  # asynchronous into pinned memory
        return self.lend(buf, k)

    def lend(self, buf: wp.array, k: int) -> np.ndarray:
        """The first k rows of `buf` (filled), given back once no view of them is left."""
        whole = buf.numpy()
        weakref.finalize(whole, self._give_back, buf)
        return whole[:k]

    def borrow(self) -> wp.array | None:
        """A free buffer shaped as the device array, or None while `keep` are lent."""
        with self._lock:
            if self._free:
                return self._free.pop()
            if self._made >= self._keep:
                return None
            self._made += 1
        like = self._like
        return wp.empty(like.shape, dtype=like.dtype, device="cpu", pinned=True)

    def _give_back(self, buf: wp.array) -> None:
        with self._lock:
            self._free.append(buf)


def _host(arr: wp.array, k: int, pools: dict[int, _HostBuffers]) -> np.ndarray:
    """The first k rows of `arr` as a host array that the next draw does not overwrite: out
    of a CUDA device through pinned buffers (`_HostBuffers`), out of the CPU renderer's own
    buffer as a copy."""
    if not arr.device.is_cuda:
        return arr[:k].numpy().copy()
    if id(arr) not in pools:
        pools[id(arr)] = _HostBuffers(arr)
    return pools[id(arr)].copy(k)


class _Drawn:
    """A picture already on the host (the CPU renderer, depth or segmentation, many chunks)."""

    def __init__(self, images: Images) -> None:
        self._images = images

    def result(self) -> Images:
        return self._images


class _Copying:
    """A picture whose RGB bytes are on their way to a pinned host buffer on the copy stream;
    `result` waits for them (on the collecting thread, while the next picture draws)."""

    def __init__(
        self,
        copied: wp.Event,
        pool: _HostBuffers,
        buf: wp.array,
        shape: tuple[int, ...],
        rest: tuple[np.ndarray | None, np.ndarray | None],
    ) -> None:
        self._copied, self._pool, self._buf = copied, pool, buf
        self._shape, self._rest = shape, rest

    def result(self) -> Images:
        wp.synchronize_event(self._copied)
        rgb = self._pool.lend(self._buf, self._shape[0]).reshape(self._shape)
        return Images(rgb, *self._rest)


class BatchRenderer:
    """Draws up to `slots` worlds at a time (more are drawn in turn) for the given cameras."""

    def __init__(
        self,
        mjm: mujoco.MjModel,
        cameras: list[CameraSpec],
        slots: int,
        device: str = "cpu",
        turns: DeviceTurns | None = None,
    ) -> None:
        """`turns`: the engine's, where it steps on the same CUDA device: the renderer then
        launches on a stream of its own, in its turns (service/core/sim/device_turns.py)."""
        self.cameras = {c.name: c for c in cameras}
        self.slots = int(slots)
        self.device = wp.get_device(device)
        self.nq = mjm.nq
        t0 = time.perf_counter()
        with wp.ScopedDevice(self.device):
            self._m = mjw.put_model(mjm)
            data = mujoco.MjData(mjm)
            mujoco.mj_kinematics(mjm, data)  # no contacts: the render batch never steps
            self._d = mjw.put_data(mjm, data, nworld=self.slots, nconmax=1, njmax=1)
            self._qpos = np.zeros((self.slots, mjm.nq), dtype=np.float32)
            # CUDA: the states go up from two pinned buffers in turn, without the host waiting
            # for the picture before (from pageable memory it would, holding the device's turn)
            pinned = self.device.is_cuda
            self._qpos_up = [
                wp.empty((self.slots, mjm.nq), dtype=float, device="cpu", pinned=pinned)
                for _ in range(2 if pinned else 0)
            ]
            self._qpos_sent: list[wp.Event | None] = [None, None]
            self._rgb = {  # the RGB bytes of each camera that draws RGB, on the device
                c.name: wp.zeros((self.slots, 3 * c.width * c.height), dtype=wp.uint8)
                for c in cameras
                if c.rgb
            }
            self._ctx = {
                c.name: mjw.create_render_context(
                    mjm,
                    nworld=self.slots,
                    cam_res=[(c.width, c.height)],
                    render_rgb=[c.rgb],
                    render_depth=[c.depth],
                    render_seg=[c.seg],
                    cam_active=[c.id],
                    background_color=(0.1, 0.11, 0.13, 1.0),
                )
                for c in cameras
            }
        self._pools: dict[int, _HostBuffers] = {}  # pinned host buffers per device array
        # CUDA: RGB bytes in two device buffers per camera, taken in turn, so that a picture's
        # bytes are copied out on a stream of their own while the next picture draws into the
        # other; `_copied` holds each buffer's last copy, which the next draw into it waits for
        self._turn = dict.fromkeys(self._rgb, 0)
        self._copied: dict[tuple[str, int], wp.Event] = {}
        self._copy_stream = render_stream(self.device) if self.device.is_cuda else None
        self._turns = turns if self.device.is_cuda else None
        self._stream = render_stream(self.device) if self._turns is not None else None
        if self.device.is_cuda:
            with wp.ScopedDevice(self.device):
                self._rgb_next = {name: wp.zeros_like(buf) for name, buf in self._rgb.items()}
        else:
            self._rgb_next = dict(self._rgb)
        self.build_s = time.perf_counter() - t0
        self.compile_s = 0.0  # the first render of each camera compiles (or loads) its kernel

    def warm(self) -> float:
        """Draw every camera once (compiling or loading the kernels); seconds it took."""
        t0 = time.perf_counter()
        home = np.asarray(self._d.qpos.numpy()[:1], dtype=np.float64)
        for name in self.cameras:
            self.render(home, name)
        self.compile_s = time.perf_counter() - t0
        return self.compile_s

    def render(self, qpos: np.ndarray, camera: str) -> Images:
        """What `camera` sees in each world of `qpos` (k, nq); KeyError for an unknown camera."""
        return self.launch(qpos, camera).result()

    def launch(self, qpos: np.ndarray, camera: str) -> _Drawn | _Copying:
        """`render`, started: its `result()` waits for the pictures. On CUDA, for up to
        `slots` worlds of a camera that draws RGB, the drawing is queued and its RGB bytes go
        to a pinned host buffer on the copy stream: the caller may start the next picture
        before this one's pixels have arrived (they are 201 MB for 16,384 64x64 worlds)."""
        spec = self.cameras[camera]
        qpos = np.asarray(qpos).reshape(-1, self.nq)
        with self._own_stream():
            if self._copy_stream is not None and spec.rgb and 0 < len(qpos) <= self.slots:
                started = self._launch_copying(qpos, spec)
                if started is not None:
                    return started
            return _Drawn(self._render_all(qpos, spec))

    @contextlib.contextmanager
    def _own_stream(self) -> Iterator[None]:
        """Launches on the renderer's own stream, in its turn, where it shares the device with
        an engine; else on the device's current stream."""
        if self._turns is None or self._stream is None:
            yield
            return
        with self._turns.render_turn(), wp.ScopedStream(self._stream, sync_enter=False):
            yield

    def _launch_copying(self, qpos: np.ndarray, spec: CameraSpec) -> _Copying | None:
        k, name = len(qpos), spec.name
        pool = self._pools.setdefault(id(self._rgb[name]), _HostBuffers(self._rgb[name]))
        buf = pool.borrow()
        if buf is None:  # every pinned buffer is still being sent: the plain way
            return None
        turn = self._turn[name] = 1 - self._turn[name]
        out = (self._rgb, self._rgb_next)[turn][name]
        with wp.ScopedDevice(self.device):
            stream = wp.get_stream(self.device)
            if (before := self._copied.get((name, turn))) is not None:
                stream.wait_event(before)  # that buffer's last copy is done before we overwrite
            self._upload(qpos)
            self._draw(spec, k, out)
            rest = self._depth_seg(spec, k)
            drawn = stream.record_event()
            self._copy_stream.wait_event(drawn)
            wp.copy(buf, out[:k], count=k * out.shape[1], stream=self._copy_stream)
            copied = self._copied[(name, turn)] = self._copy_stream.record_event()
        shape = (k, spec.height, spec.width, 3)
        return _Copying(copied, pool, buf, shape, rest)

    def _upload(self, qpos: np.ndarray) -> None:
        """The k states into the render batch's first k slots, on the current stream."""
        k = len(qpos)
        if not self._qpos_up:
            self._qpos[:k] = qpos
            self._d.qpos.assign(self._qpos)
            return
        self._qpos_sent.reverse()
        self._qpos_up.reverse()
        if (sent := self._qpos_sent[0]) is not None:
            wp.synchronize_event(sent)  # this buffer's last upload (two pictures ago) is done
        host = self._qpos_up[0]
        host.numpy()[:k] = qpos
        wp.copy(self._d.qpos, host, count=k * self.nq)
        self._qpos_sent[0] = wp.get_stream(self.device).record_event()

    def _render_all(self, qpos: np.ndarray, spec: CameraSpec) -> Images:
        qpos = np.asarray(qpos).reshape(-1, self.nq)
        parts = [
            self._render_chunk(qpos[i : i + self.slots], spec)
            for i in range(0, len(qpos), self.slots)
        ]
        if len(parts) == 1:  # the usual case: no second 201 MB copy by concatenating one part
            return Images(*parts[0])
        return Images(
            *(
                None if not parts or parts[0][j] is None else np.concatenate([p[j] for p in parts])
                for j in range(3)
            )
        )

    def _draw(self, spec: CameraSpec, k: int, rgb: wp.array | None = None) -> None:
        """The device's work for one picture of the first k slots (launches only). Not captured
        as a CUDA graph: a capture on the stream the engine steps on would take the engine's
        own launches into it."""
        rc, d = self._ctx[spec.name], self._d
        d.nworld = k  # every launch below covers the first k slots only
        try:
            mjw.kinematics(self._m, d)
            mjw.camlight(self._m, d)
            mjw.refit_bvh(self._m, d, rc)
            mjw.render(self._m, d, rc)
        finally:
            d.nworld = self.slots
        if spec.rgb:
            n = spec.width * spec.height
            out = self._rgb[spec.name] if rgb is None else rgb
            wp.launch(_rgb_bytes, dim=(k, n), inputs=[rc.rgb_data], outputs=[out])

    def _render_chunk(
        self, qpos: np.ndarray, spec: CameraSpec
    ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        k = len(qpos)
        with wp.ScopedDevice(self.device):
            if (copying := self._copied.get((spec.name, 0))) is not None:
                wp.get_stream(self.device).wait_event(copying)  # its buffer is drawn into next
            self._upload(qpos)
            self._draw(spec, k)
            h, w = spec.height, spec.width
            rgb = None
            if spec.rgb:
                rgb = _host(self._rgb[spec.name], k, self._pools).reshape(k, h, w, 3)
            depth, seg = self._depth_seg(spec, k)
        return rgb, depth, seg

    def _depth_seg(self, spec: CameraSpec, k: int) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Depth and segmentation of the last draw, on the host (None: not drawn)."""
        rc, h, w = self._ctx[spec.name], spec.height, spec.width
        depth = seg = None
        if spec.depth:
            depth = _host(rc.depth_data, k, self._pools).reshape(k, h, w)
        if spec.seg:
            seg = _host(rc.seg_data, k, self._pools)[:, : h * w, 0]
            seg = seg.reshape(k, h, w).astype(np.int32)
        return depth, seg
