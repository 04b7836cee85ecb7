"""All service settings in one place; every field can also come from an ARMFLEET_* variable.

Precedence: a `armfleet serve` option the user typed > ARMFLEET_* variable > the default here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

from service.types import Mode


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="ARMFLEET_")

    worlds: int = Field(16, ge=1, le=1_048_576, description="number of parallel worlds")
    device: str = Field("cpu", description="warp device: cpu, cuda or cuda:N")
    host: str = Field("127.0.0.1", description="bind address (loopback by default)")
    port: int = Field(8000, ge=0, le=65535, description="TCP port")
    shards: int = Field(
        0, ge=0, le=256, description="CPU worker shards (one per core); 0 = auto by batch size"
    )
    mode: Mode = Field(Mode.REALTIME, description="how time advances: realtime, fast or paused")
    control_hz: float = Field(60.0, gt=0, le=1000, description="control ticks per second")
    physics_dt: float = Field(0.002, gt=0, le=0.01, description="approximate physics step [s]")
    max_body_bytes: int = Field(1 << 20, description="larger request bodies get 413")
    log_level: Literal["debug", "info", "warning", "error"] = Field(
        "info", description="debug, info, warning or error"
    )
    data_dir: Path = Field(
        Path("~/.local/share/armfleet"), description="where snapshots and recordings are kept"
    )
    restore: str | None = Field(
        None, description="start from this snapshot: latest or a snapshot name"
    )
    save_on_exit: bool = Field(
        True, description="save snapshot `latest` on a clean stop (SIGTERM, Ctrl-C)"
    )
    record: Path | None = Field(None, description="record to this MCAP file from the start")
    record_worlds: str | None = Field(
        None, description="worlds whose states are recorded, e.g. 0-7,12 (default: first 8)"
    )
    record_rate: float = Field(
        30.0, gt=0, le=1000, description="recorded states per simulated second"
    )
    record_queue: int = Field(
        2048,
        ge=16,
        le=1_000_000,
        description="items a recording may hold waiting for the disk; when full it stops",
    )
    foxglove: bool = Field(False, description="serve Foxglove's WebSocket protocol")
    foxglove_port: int = Field(8765, ge=0, le=65535, description="Foxglove WebSocket port")
    foxglove_worlds: str | None = Field(
        None, description="worlds shown in Foxglove, e.g. 0-3 (default: first 8)"
    )
    foxglove_rate: float = Field(30.0, gt=0, le=240, description="Foxglove frames per second")
