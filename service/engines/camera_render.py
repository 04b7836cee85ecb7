"""BatchRenderer: MuJoCo Warp's batch renderer drawing given world states, for any engine.

Every engine hands over the asked worlds' qpos (`Renderable.render_state`); this module
copies those rows into a render batch of its own (an mjwarp Model and Data of `slots` worlds
on the engine's device), recomputes the kinematics there and ray-casts the cameras. So the
same state gives the same pixels whichever engine stepped it, the engine's own arrays are
never touched from the render thread, and only the asked worlds and the asked camera are
drawn: one render context per camera, launched over the first k slots only.

Nothing here is thread-safe: one thread (the camera feed's) owns a BatchRenderer.
"""

from __future__ import annotations

import time
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
        return Images(
            *(
                None if not parts or parts[0][j] is None else np.concatenate([p[j] for p in parts])
                for j in range(3)
            )
        )

    def _render_chunk(
        self, qpos: np.ndarray, spec: CameraSpec
    ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        k = len(qpos)
        rc = self._ctx[spec.name]
        d = self._d
        with wp.ScopedDevice(self.device):
            self._qpos[:k] = qpos
            d.qpos.assign(self._qpos)
            d.nworld = k  # every launch below covers the first k slots only
            try:
                mjw.kinematics(self._m, d)
                mjw.camlight(self._m, d)
                mjw.refit_bvh(self._m, d, rc)
                mjw.render(self._m, d, rc)
            finally:
                d.nworld = self.slots
            h, w = spec.height, spec.width
            rgb = depth = seg = None
            if spec.rgb:  # packed 0xAARRGGBB little-endian: bytes B, G, R, A
                packed = rc.rgb_data.numpy()[:k].view(np.uint8).reshape(k, h, w, 4)
                rgb = np.ascontiguousarray(packed[..., 2::-1])
            if spec.depth:
                depth = rc.depth_data.numpy()[:k].reshape(k, h, w).copy()
            if spec.seg:
                seg = rc.seg_data.numpy()[:k, : h * w, 0].reshape(k, h, w).astype(np.int32)
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
