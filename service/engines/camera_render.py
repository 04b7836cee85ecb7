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

import threading
import time
import weakref
from dataclasses import dataclass

import mujoco
import mujoco_warp as mjw
import numpy as np
import warp as wp

from service.core.camera_feed import CameraFeed
from service.core.cameras import CameraSpec, camera_specs
from service.core.loop import SimLoop
from service.core.settings import Settings


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

    def __init__(self, like: wp.array, keep: int = 4) -> None:
        self._like = like
        self._keep = keep
        self._free: list[wp.array] = []
        self._made = 0
        self._lock = threading.Lock()

    def copy(self, k: int) -> np.ndarray:
        """The first k rows of the device array, in a host array of their own."""
        view = self._like[:k]
        buf = self._borrow()
        if buf is None:
            return view.numpy()
        wp.copy(buf, view, count=view.size)
        wp.synchronize_stream(self._like.device.stream)  # asynchronous into pinned memory
        whole = buf.numpy()
        weakref.finalize(whole, self._give_back, buf)
        return whole[:k]

    def _borrow(self) -> wp.array | None:
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
    if arr.ptr not in pools:
        pools[arr.ptr] = _HostBuffers(arr)
    return pools[arr.ptr].copy(k)


class BatchRenderer:
    """Draws up to `slots` worlds at a time (more are drawn in turn) for the given cameras."""

    def __init__(
        self, mjm: mujoco.MjModel, cameras: list[CameraSpec], slots: int, device: str = "cpu"
    ) -> None:
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
        spec = self.cameras[camera]
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

    def _draw(self, spec: CameraSpec, k: int) -> None:
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
            wp.launch(_rgb_bytes, dim=(k, n), inputs=[rc.rgb_data], outputs=[self._rgb[spec.name]])

    def _render_chunk(
        self, qpos: np.ndarray, spec: CameraSpec
    ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        k = len(qpos)
        rc = self._ctx[spec.name]
        with wp.ScopedDevice(self.device):
            self._qpos[:k] = qpos
            self._d.qpos.assign(self._qpos)
            self._draw(spec, k)
            h, w = spec.height, spec.width
            rgb = depth = seg = None
            if spec.rgb:
                rgb = _host(self._rgb[spec.name], k, self._pools).reshape(k, h, w, 3)
            if spec.depth:
                depth = _host(rc.depth_data, k, self._pools).reshape(k, h, w)
            if spec.seg:
                seg = _host(rc.seg_data, k, self._pools)[:, : h * w, 0]
                seg = seg.reshape(k, h, w).astype(np.int32)
        return rgb, depth, seg


def camera_feed(loop: SimLoop, settings: Settings) -> CameraFeed:
    """The service's cameras: the scene's cameras at the sizes and outputs of the settings,
    drawn by a BatchRenderer on the engine's device (CPU engines: warp's CPU device), built
    and warmed on the feed's own thread."""
    batch = loop.batch
    mjm = batch.robot.mjm
    specs = camera_specs(mjm, settings.camera_size, settings.camera_outputs, settings.cameras)
    device = batch.device_name if batch.device_name.startswith("cuda") else "cpu"
    slots = min(settings.camera_batch, batch.nworld)
    return CameraFeed(loop, specs, lambda: BatchRenderer(mjm, specs, slots, device))
