"""The service's camera feed: which device draws, and when its renderer is built.

Apart from camera_render.py so that choosing costs no import of MuJoCo Warp: the renderer
module (and with it MuJoCo Warp, about 3 s of CPU to import) is loaded on the feed's render
thread when the renderer is built. On a GPU it is built when the service starts, so the first
picture does not wait for compiles; on the CPU when the first picture or the camera list is
asked (`CameraFeed.open`): there the build costs seconds of the cores that step the worlds,
and a CPU service that nobody asks for pictures should not pay them.
"""

from __future__ import annotations

from service.core.cameras.catalog import camera_specs
from service.core.cameras.feed import CameraFeed, ImageRenderer
from service.core.cameras.settings import CameraSettings
from service.core.sim.loop import SimLoop


def _same_device(a: str, b: str) -> bool:
    """Whether two device names are one device ("cuda" is warp's default CUDA device, 0)."""

    def canonical(name: str) -> str:
        return "cuda:0" if name == "cuda" else name

    return canonical(a) == canonical(b)


def camera_feed(loop: SimLoop, settings: CameraSettings) -> CameraFeed:
    """The scene's cameras at the sizes and outputs of the settings, drawn by a BatchRenderer
    on --camera-device, else on the engine's device (CPU engines: warp's CPU device). On a
    device of its own the renderer takes no turns with the engine
    (service/core/sim/device_turns.py): nothing else launches there."""
    batch = loop.batch
    mjm = batch.robot.mjm
    specs = camera_specs(mjm, settings.size, settings.outputs, settings.per_camera)
    engine = batch.device_name if batch.device_name.startswith("cuda") else "cpu"
    device = settings.device or engine
    slots = min(settings.batch, batch.nworld)
    turns = getattr(batch, "device_turns", None) if _same_device(device, engine) else None

    def build() -> ImageRenderer:
        from service.engines.camera_render import BatchRenderer

        return BatchRenderer(mjm, specs, slots, device, turns)

    return CameraFeed(loop, specs, build, at_start=device.startswith("cuda"))
