"""The safety system's two commands: `protective_stop` (hold the arm where it is and stop the
world) and `unlock_protective_stop` (back to NORMAL, as the Dashboard's line of that name).

Why commands, run through `Control` like every other: the hold and the stop must be one step
under the order lock. A command accepted between "hold here" and "stopped" would move the arm
of a world its safety system had just stopped; staged together, every later command meets a
stopped world and is refused (409, core/sim/safety.py). And like every other command they are
announced: the recorder keeps them, so a replay stops and unlocks where the run did.

Who raises a stop, on every world: the clearance watch (clearance_watch.py: a commanded
target into a fixed obstacle), the torque watch (torque_watch.py: a joint held at its torque
limit), and a user: `POST /v1/worlds/{w}/trigger_protective_stop`, the WebSocket op of that
name, ur_rtde's `triggerProtectiveStop` on a world with UR ports. Who unlocks it:
`POST /v1/worlds/{w}/unlock_protective_stop`, the WebSocket op of that name, the Dashboard; a
reset clears it too (world.py).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.core.commands.base import Announcement, Command, Door, no_fields, world_ack
from service.core.errors import BadCommand, Conflict
from service.core.sim import arithmetic, rules
from service.core.sim.loop_types import CommandResult
from service.core.sim.safety import PROTECTIVE_STOP, UNLOCK_AFTER_S

__all__ = ["ProtectiveStop", "UnlockProtectiveStop"]

log = logging.getLogger("armfleet.safety")
ARM = 6  # the arm's joints come first


@dataclass(frozen=True)
class ProtectiveStop(
    Command["CommandResult | None"],
    kind="protective_stop",
    op="trigger_protective_stop",
    http=("trigger_protective_stop",),
):
    """Hold `world`'s arm at `q` (6,) (where it is now), stop its trajectory, and set its
    safety mode to PROTECTIVE_STOP with the cause `why`; None (nothing staged) when it is
    stopped already (the first cause is kept). The safety watches raise it, and so may a
    user (`triggered`: ur_rtde's triggerProtectiveStop on any surface)."""

    world: int
    q: tuple[float, ...]
    why: str

    @property
    def touches(self) -> Sequence[int]:
        return (self.world,)

    @classmethod
    def create(cls, door: Door, world: object, q: Any, why: str) -> ProtectiveStop:
        w = rules.world_id(world, door.nworld)
        held = np.asarray(q, dtype=np.float64).reshape(-1)[:ARM]
        if held.shape != (ARM,) or not np.isfinite(held).all():
            raise BadCommand("q", f"a protective stop holds {ARM} finite joint angles, got {q!r}")
        return cls(w, tuple(held.tolist()), str(why))

    @classmethod
    def triggered(cls, door: Door, world: object, where: str) -> ProtectiveStop:
        """A user's stop of `world`, sent over `where` (a surface's words): the arm held at its
        angles of the latest snapshot, as the watches hold it."""
        w = rules.world_id(world, door.nworld)
        q = door.loop.latest.position[w, :ARM]
        return cls.create(door, w, q, f"triggered by the user ({where})")

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> ProtectiveStop:
        no_fields("trigger_protective_stop", body)
        return cls.triggered(door, world, "the WebSocket op trigger_protective_stop")

    def ack(self, door: Door, msg_id: Any, world: int, result: CommandResult | None) -> dict:
        tick = door.loop.tick if result is None else result.tick
        why = door.loop.safety.why(world)
        return world_ack(msg_id, world, tick=tick, safety_mode="PROTECTIVE_STOP", why=why)

    def stage(self, door: Door, source: str) -> CommandResult | None:
        loop = door.loop
        if loop.safety.mode(self.world) == PROTECTIVE_STOP:
            return None
        door.trajectories.cancel([self.world], dispatch=False)
        spec, values = door.spec, dict(enumerate(self.q))
        held = loop.commands.stage_rows(
            [self.world], lambda _w, row: arithmetic.replace_targets(spec, row, values), range(ARM)
        )
        loop.safety.stop(self.world, self.why)
        log.warning("world %d: protective stop: %s", self.world, self.why)
        return held[0]

    def announce(self, door: Door, result: CommandResult | None) -> Announcement | None:
        if result is None:
            return None
        worlds = np.array([self.world], dtype=np.int64)
        return Announcement(worlds, result.target[None], result.tick, {"why": self.why})

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> ProtectiveStop:
        return cls.create(door, rec["worlds"][0], rec["targets"][0], rec.get("why", "replayed"))


@dataclass(frozen=True)
class UnlockProtectiveStop(
    Command[int],
    kind="unlock_protective_stop",
    op="unlock_protective_stop",
    http=("unlock_protective_stop",),
):
    """Back to NORMAL, as UR's Dashboard `unlock protective stop`: refused (409) within
    UNLOCK_AFTER_S of the stop, the robot's rule; a world that is not stopped stays NORMAL.
    The arm stays where the stop held it. Returns the tick it was unlocked at. `at_once`:
    whatever the stop's age (a replay: the run's own unlock passed that rule already)."""

    world: int
    at_once: bool = False

    @property
    def touches(self) -> Sequence[int]:
        return (self.world,)

    @classmethod
    def create(cls, door: Door, world: object) -> UnlockProtectiveStop:
        return cls(rules.world_id(world, door.nworld))

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> UnlockProtectiveStop:
        no_fields(cls.kind, body)
        return cls.create(door, world)

    def stage(self, door: Door, source: str) -> int:
        safety = door.loop.safety
        if self.at_once:
            safety.clear([self.world])
        elif not safety.unlock(self.world):
            age = safety.age(self.world)
            raise Conflict(
                f"world {self.world} was protective-stopped {age:.1f} s ago: a protective "
                f"stop may be unlocked {UNLOCK_AFTER_S:g} s after it at the earliest (the "
                "robot's rule; a reset clears it at once)",
                "world",
            )
        return door.loop.tick

    def announce(self, door: Door, result: int) -> Announcement:
        worlds = np.array([self.world], dtype=np.int64)
        return Announcement(worlds, door.loop.commands.pending_targets(worlds), result + 1)

    def ack(self, door: Door, msg_id: Any, world: int, result: int) -> dict[str, Any]:
        return world_ack(msg_id, world, tick=result, safety_mode="NORMAL")

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> UnlockProtectiveStop:
        return cls(rules.world_id(rec["worlds"][0], door.nworld), at_once=True)
