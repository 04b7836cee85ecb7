"""What the Foxglove surfaces are asked for: the live WebSocket server (port, worlds, rate,
cameras) and the camera recording (an MCAP file of Foxglove's image and calibration messages).

Why models of their own: each surface is built from its own model, plus what the registry
hands every surface (`ServiceFacts`: the bind address, access, the camera rate). World lists
and camera names are checked against the worlds and the scene by the service's `Settings`,
which holds both sides. A field's `validation_alias` is its flat name (`ARMFLEET_FOXGLOVE_PORT`,
`--camera-record-worlds`), kept from the flat model of before.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel

from service.core.process.flat_names import BY_BOTH, flat


class FoxgloveSettings(BaseModel):
    """Foxglove live (`--foxglove`, `--foxglove-port`, `--foxglove-worlds`, ...)."""

    model_config = BY_BOTH

    enabled: bool = flat("foxglove", False, "serve Foxglove's WebSocket protocol")
    port: int = flat("foxglove_port", 8765, "Foxglove WebSocket port", ge=0, le=65535)
    worlds: str | None = flat(
        "foxglove_worlds", None, "worlds shown in Foxglove, e.g. 0-3 (default: first 8)"
    )
    rate: float = flat("foxglove_rate", 30.0, "Foxglove frames per second", gt=0, le=240)
    cameras: str = flat(
        "foxglove_cameras",
        "",
        "cameras shown in Foxglove for --foxglove-worlds, e.g. wrist,overview",
    )


class CameraRecordSettings(BaseModel):
    """The camera recording (`--camera-record`, `--camera-record-cameras`, ...-worlds)."""

    model_config = BY_BOTH

    path: Path | None = flat(
        "camera_record", None, "record camera images (JPEG) and calibrations to this MCAP file"
    )
    cameras: str = flat("camera_record_cameras", "wrist", "cameras --camera-record records")
    worlds: str = flat("camera_record_worlds", "0", "worlds --camera-record records, e.g. 0-3")
