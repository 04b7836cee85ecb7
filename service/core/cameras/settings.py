"""What the cameras are asked to draw: the size and outputs of every camera, per-camera
changes, how many worlds one render draws, on which device, and how often surfaces show them.

Why a model of its own: the renderer is built from these once, at start
(`engines/cameras.camera_feed`), and surfaces read only the rate. Each string is parsed
here (a bad one names its setting); what needs another part of the settings (the render
batch's pixel limit against the number of worlds, camera names against the scene) is checked
by the service's `Settings`, which holds both. A field's `validation_alias` is its flat name
(`ARMFLEET_CAMERA_SIZE`, `--cameras`), kept from the flat model of before.
"""

from __future__ import annotations

from pydantic import BaseModel, model_validator

from service.core.process.flat_names import BY_BOTH, flat


class CameraSettings(BaseModel):
    """The cameras (`--camera-size`, `--camera-outputs`, `--cameras`, `--camera-batch`, ...)."""

    model_config = BY_BOTH

    size: str = flat(
        "camera_size", "128x96", "image size of every camera, WIDTHxHEIGHT (1..4096 a side)"
    )
    outputs: str = flat(
        "camera_outputs",
        "rgb,depth",
        "what cameras draw unless --cameras says otherwise: rgb, depth, seg",
    )
    per_camera: str = flat(
        "cameras",
        "",
        "per camera: NAME=WxH[:OUTPUTS] or NAME=off, comma-separated, e.g. "
        "wrist=320x240:rgb+depth,overview=off (OUTPUTS joined by +)",
    )
    batch: int = flat(
        "camera_batch",
        16,
        "worlds one render draws at once (more are drawn in turn)",
        ge=1,
        le=65_536,
    )
    device: str = flat(
        "camera_device",
        "",
        "device the cameras draw on: cpu, cuda or cuda:N, e.g. a GPU of their own "
        "beside the engine's (default: the engine's GPU; CPU engines: warp's CPU device)",
        pattern=r"^(|cpu|cuda(:[0-9]+)?)$",
    )
    rate: float = flat(
        "camera_rate",
        10.0,
        "images a second per camera on Foxglove and in --camera-record",
        gt=0,
        le=60,
    )

    @model_validator(mode="after")
    def _strings_parse(self) -> CameraSettings:
        from service.core.cameras.catalog import parse_outputs, parse_overrides, parse_size

        parse_size(self.size, "camera_size")  # ValueError names setting + limit
        parse_outputs(self.outputs, "camera_outputs")
        parse_overrides(self.per_camera)
        return self

    def largest_pixels(self) -> int:
        """Pixels of the largest image any camera draws (the default size or an override)."""
        from service.core.cameras.catalog import parse_overrides, parse_size

        sizes = [parse_size(self.size, "camera_size")]
        sizes += [c[0] for c in parse_overrides(self.per_camera).values() if c and c[0]]
        return max(w * h for w, h in sizes)

    def named(self) -> list[str]:
        """The cameras `--cameras` names (each must be one the scene has)."""
        from service.core.cameras.catalog import parse_overrides

        return list(parse_overrides(self.per_camera))
