"""Whole-world and whole-service commands: `reset` (worlds back to home), `mode` (realtime,
fast, paused) and `step` (paused only: advance exactly n ticks)."""

from __future__ import annotations

import concurrent.futures
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import ConfigDict, Field

from service.core.commands.base import (
    Announcement,
    Command,
    Door,
    no_fields,
    no_worlds,
    result_ack,
)
from service.core.commands.fields import Strict, WorldId, json_int
from service.core.sim import rules
from service.core.sim.loop_types import CommandResult
from service.core.sim.types import Mode

__all__ = ["Reset", "ResetResult", "SetMode", "Step"]

MAX_STEP_TICKS = 100_000


# -- request bodies ----------------------------------------------------------------------------


class ResetRequest(Strict):
    worlds: list[WorldId] | None = Field(default=None, description="omit for all worlds")

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"worlds": [0, 3]}]})


class ModeRequest(Strict):
    mode: Mode

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"mode": "fast"}]})


class StepRequest(Strict):
    ticks: json_int(minimum=1, maximum=MAX_STEP_TICKS) = 1  # type: ignore[valid-type]

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"ticks": 60}]})


@dataclass(frozen=True)
class ResetResult:
    """Worlds sent back to `home`, their targets afterwards (k, 7), and the effective tick."""

    worlds: list[int]
    tick: int
    targets: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class Reset(Command[ResetResult], kind="reset", op="reset", http=("reset",)):
    """Send worlds (all when None) back to `home`, state and targets."""

    worlds: list[int] | None

    @property
    def touches(self) -> Sequence[int] | None:
        return self.worlds

    @classmethod
    def create(cls, door: Door, worlds: Sequence[object] | None) -> Reset:
        return cls(None if worlds is None else rules.world_ids(worlds, door.nworld))

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> Reset:
        no_fields(cls.kind, body)
        return cls([world])

    def stage(self, door: Door, source: str) -> ResetResult:
        ids = list(range(door.nworld)) if self.worlds is None else self.worlds
        tick = door.loop.commands.reset(ids)
        door.loop.safety.clear(ids)  # a new episode: back at home, no protective stop
        return ResetResult(ids, tick, np.tile(door.loop.batch.home_target, (len(ids), 1)))

    def announce(self, door: Door, result: ResetResult) -> Announcement:
        return Announcement(np.array(result.worlds, dtype=np.int64), result.targets, result.tick)

    def ack(self, door: Door, msg_id: Any, world: int, result: ResetResult) -> dict[str, Any]:
        return result_ack(msg_id, CommandResult(world, result.targets[0], [], result.tick))

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> Reset:
        return cls.create(door, rec["worlds"])


@dataclass(frozen=True)
class SetMode(Command[int], kind="mode", http=("mode", "pause", "resume"), replayed=False):
    """Switch realtime / fast / paused; the tick at which the switch happened. Not replayed:
    replay steps tick by tick whatever the mode was."""

    mode: Mode

    def stage(self, door: Door, source: str) -> int:
        door.loop.set_mode(self.mode)
        return door.loop.tick

    def announce(self, door: Door, result: int) -> Announcement:
        return no_worlds(result, mode=str(self.mode))


@dataclass(frozen=True)
class Step(Command["concurrent.futures.Future[int]"], kind="step", http=("step",), replayed=False):
    """Paused only: advance exactly `ticks` control ticks; the future resolves with the tick
    reached (NotPaused, 409, otherwise). Not recorded: a recording holds every tick anyway."""

    ticks: int

    def stage(self, door: Door, source: str) -> concurrent.futures.Future[int]:
        return door.loop.step(self.ticks)
