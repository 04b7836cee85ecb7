"""Trajectory commands: start (`trajectory`), stop and hold (`trajectory_cancel`, op
`cancel_trajectory`) and put back one that ran when a recording started (`trajectory_resume`).

`{"op": "trajectory", "id": 7, "world": 0, "joint_names": [...], "points": [...]}` (the body
of POST /v1/worlds/{w}/trajectory) is acked with the trajectory's id and ticks;
`{"op": "cancel_trajectory", "id": 8, "world": 0}` with the stopped trajectory's status (null
when none was running).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.core.commands.base import Announcement, Command, Door, no_fields, world_ack
from service.core.commands.targets import _model
from service.core.commands.trajectory.schemas import TrajectoryBody
from service.core.commands.trajectory.spec import JointTrajectorySpec, parse
from service.core.commands.trajectory.status import Resumable, Started, TrajectoryStatus
from service.core.sim import rules

__all__ = ["CancelTrajectory", "ResumeTrajectory", "StartTrajectory"]


@dataclass(frozen=True)
class StartTrajectory(
    Command[list[Started]], kind="trajectory", op="trajectory", http=("trajectory",), moves=True
):
    """Run a validated trajectory on every world of `worlds` from one tick (see trajectory)."""

    worlds: list[int]
    spec: JointTrajectorySpec

    @property
    def touches(self) -> Sequence[int] | None:
        return self.worlds

    @classmethod
    def create(
        cls, door: Door, worlds: Sequence[object], spec: JointTrajectorySpec
    ) -> StartTrajectory:
        return cls(rules.world_ids(worlds, door.nworld), spec)

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> StartTrajectory:
        json_body = _model(TrajectoryBody, body).as_json()
        return cls([world], parse(door.spec, json_body))

    def stage(self, door: Door, source: str) -> list[Started]:
        return door.trajectories.start(self.worlds, self.spec, source, dispatch=False)

    def announce(self, door: Door, result: list[Started]) -> Announcement | None:
        if not result:
            return None
        worlds = np.array(self.worlds, dtype=np.int64)
        record = {"trajectory": self.spec.to_json()}
        return Announcement(
            worlds, door.loop.commands.pending_targets(worlds), result[0].start_tick, record
        )

    def ack(self, door: Door, msg_id: Any, world: int, result: list[Started]) -> dict[str, Any]:
        started = result[0]
        tick, json = started.start_tick, started.as_json()
        return world_ack(msg_id, world, tick=tick, trajectory=json)

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> StartTrajectory:
        """Re-run from the same tick: sampled exactly as it was."""
        return cls.create(door, rec["worlds"], parse(door.spec, rec["trajectory"]))


@dataclass(frozen=True)
class CancelTrajectory(
    Command[list[TrajectoryStatus]], kind="trajectory_cancel", op="cancel_trajectory"
):
    """Stop the worlds' running trajectories; they hold where they were. Those stopped."""

    worlds: list[int]

    @property
    def touches(self) -> Sequence[int] | None:
        return self.worlds

    @classmethod
    def create(cls, door: Door, worlds: Sequence[object]) -> CancelTrajectory:
        return cls(rules.world_ids(worlds, door.nworld))

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> CancelTrajectory:
        no_fields("cancel_trajectory", body)
        return cls([world])

    def stage(self, door: Door, source: str) -> list[TrajectoryStatus]:
        return door.trajectories.cancel(self.worlds, dispatch=False)

    def announce(self, door: Door, result: list[TrajectoryStatus]) -> Announcement | None:
        if not result:
            return None
        worlds = np.array([s.world for s in result], dtype=np.int64)
        tick = int(result[0].finished_tick or 0) + 1  # the hold starts here
        return Announcement(worlds, door.loop.commands.pending_targets(worlds), tick)

    def ack(
        self, door: Door, msg_id: Any, world: int, result: list[TrajectoryStatus]
    ) -> dict[str, Any]:
        status = result[0] if result else None
        done = status is not None and status.finished_tick is not None
        tick = status.finished_tick + 1 if done else door.loop.tick + 1  # type: ignore[union-attr,operator]
        return world_ack(
            msg_id, world, tick=tick, trajectory=None if status is None else status.as_json()
        )

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> CancelTrajectory:
        return cls.create(door, rec["worlds"])


@dataclass(frozen=True)
class ResumeTrajectory(Command[tuple[Started, int]], kind="trajectory_resume"):
    """Put back a trajectory that ran when a recording started (replay; see Resumable)."""

    run: Resumable

    @property
    def touches(self) -> Sequence[int]:
        return (self.run.world,)

    def stage(self, door: Door, source: str) -> tuple[Started, int]:
        return door.trajectories.resume(self.run, source)

    def announce(self, door: Door, result: tuple[Started, int]) -> Announcement:
        worlds = np.array([self.run.world], dtype=np.int64)
        record = {"trajectory": self.run.as_json()}
        return Announcement(worlds, np.array([self.run.target]), result[1], record)

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> ResumeTrajectory:
        worlds = rules.world_ids(rec["worlds"], door.nworld)
        body = rec["trajectory"]
        spec, start = parse(door.spec, body), body["resume_from"]
        run = Resumable(worlds[0], spec, start["start_tick"], start["target"], start["velocity"])
        return cls(run)
