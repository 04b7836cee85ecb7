"""All service settings in one place; every field can also come from an ARMFLEET_* variable.

Precedence: a `armfleet serve` option the user typed > ARMFLEET_* variable > the default here.
"""

from __future__ import annotations

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
