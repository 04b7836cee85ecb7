"""What the simulation is asked to be: how many worlds, of which scene, at what rates, and how
time advances. Why a model of its own: the engine and the loop read these and nothing else of
the service's settings; the scene is checked here, before anything is built.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, model_validator

from service.core.process.engine_priority import Setting
from service.core.sim.physics import DEFAULT_PHYSICS_DT
from service.core.sim.scene_check import check_scene
from service.core.sim.types import Mode


class SimSettings(BaseModel):
    """The simulation (`--worlds`, `--scene`, `--mode`, `--control-hz`, `--physics-dt`,
    `--ticks-first`, `--command-wait-s`, `--engine-priority`)."""

    model_config = ConfigDict(extra="forbid")

    worlds: int = Field(16, ge=1, le=1_048_576, description="number of parallel worlds")
    scene: Path | None = Field(
        None,
        description="your cell's MJCF, which brings the arm in with <include "
        'file="ur10e_2f140.xml"/> (default: the table and cube); checked before serving',
    )
    mode: Mode = Field(Mode.REALTIME, description="how time advances: realtime, fast or paused")
    control_hz: float = Field(60.0, gt=0, le=1000, description="control ticks per second")
    physics_dt: float = Field(
        DEFAULT_PHYSICS_DT, gt=0, le=0.01, description="approximate physics step [s]"
    )
    ticks_first: bool = Field(
        True,
        description="in real time, commands take only the time the ticks leave: when the "
        "ticks run late, commands wait for a later tick (in order) rather than slow the worlds",
    )
    command_wait_s: float = Field(
        1.0,
        gt=0,
        le=60,
        description="ticks first: a command that finds no turn beside the ticks within this "
        "many seconds is refused as busy (WebSocket error, HTTP 503), not run over their time",
    )

    engine_priority: Setting = Field(
        "auto",
        description="in real time, the threads that step the worlds run 10 nice steps above "
        "the process when it may (root, CAP_SYS_NICE or RLIMIT_NICE): auto (the log says "
        "which it was) or off",
    )

    @model_validator(mode="after")
    def _scene_can_be_served(self) -> SimSettings:
        if self.scene is not None:
            check_scene(self.scene)  # SceneError (a ValueError) says what is wrong
        return self
