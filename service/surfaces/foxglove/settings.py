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

from pydantic import BaseModel, ConfigDict, Field

_BY_BOTH = ConfigDict(extra="forbid", validate_by_name=True, validate_by_alias=True)


class FoxgloveSettings(BaseModel):
    """Foxglove live (`--foxglove`, `--foxglove-port`, `--foxglove-worlds`, ...)."""

    model_config = _BY_BOTH

    enabled: bool = Field(
        False, validation_alias="foxglove", description="serve Foxglove's WebSocket protocol"
    )
    port: int = Field(
        8765,
        ge=0,
        le=65535,
        validation_alias="foxglove_port",
        description="Foxglove WebSocket port",
    )
    worlds: str | None = Field(
        None,
        validation_alias="foxglove_worlds",
        description="worlds shown in Foxglove, e.g. 0-3 (default: first 8)",
    )
    rate: float = Field(
        30.0,
        gt=0,
        le=240,
        validation_alias="foxglove_rate",
        description="Foxglove frames per second",
    )
    cameras: str = Field(
        "",
        validation_alias="foxglove_cameras",
        description="cameras shown in Foxglove for --foxglove-worlds, e.g. wrist,overview",
    )


class CameraRecordSettings(BaseModel):
    """The camera recording (`--camera-record`, `--camera-record-cameras`, ...-worlds)."""

    model_config = _BY_BOTH

    path: Path | None = Field(
        None,
        validation_alias="camera_record",
        description="record camera images (JPEG) and calibrations to this MCAP file",
    )
    cameras: str = Field(
        "wrist",
        validation_alias="camera_record_cameras",
        description="cameras --camera-record records",
    )
    worlds: str = Field(
        "0",
        validation_alias="camera_record_worlds",
        description="worlds --camera-record records, e.g. 0-3",
    )
