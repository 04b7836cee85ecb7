"""What a trajectory's owner is told: ids and ticks when it starts, status and outcome after.

Plain frozen dataclasses so that every surface (HTTP, WebSocket, ROS 2 actions, rosbridge)
serialises the same facts; `as_json` is the HTTP/WebSocket shape.
"""

from __future__ import annotations

import enum
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from service.core.commands.trajectory.spec import JointTrajectorySpec


class TrajectoryState(enum.StrEnum):
    """Where a trajectory is. `running` includes settling after the end (goal tolerance)."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    ABORTED = "aborted"


class AbortReason(enum.StrEnum):
    """Why a trajectory ended before succeeding (control_msgs' error codes, and our own)."""

    PATH_TOLERANCE = "path_tolerance"  # |actual - desired| exceeded a path tolerance
    GOAL_TOLERANCE = "goal_tolerance"  # not within the goal tolerance by the goal time
    PREEMPTED = "preempted"  # a newer trajectory on the same world replaced it
    MANUAL_OVERRIDE = "manual_override"  # a target command on one of its joints took over
    RESET = "reset"  # the world was reset to home (or the whole batch was restored)
    FAULT = "fault"  # the world's physics failed and it was reset to home
    CANCELLED = "cancelled"  # cancelled by request (DELETE, action cancel)


@dataclass(frozen=True)
class Started:
    """A trajectory accepted for one world.

    id: unique in this service run; start_tick: the first tick stepped with it; end_tick: the
    tick at whose end its last point is reached (the outcome comes at or after it).
    """

    id: int
    world: int
    start_tick: int
    end_tick: int

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class TrajectoryStatus:
    """One trajectory's status, progress and feedback (control_msgs FollowJointTrajectory).

    state/reason: see TrajectoryState and AbortReason (reason is None unless aborted);
    detail: a sentence for people (which joint broke which tolerance by how much);
    tick: the last tick sampled; progress: elapsed / duration in 0..1 at that tick;
    desired, actual, error: per joint of `joint_names` at `feedback_tick` [rad] (actual and
    error are empty until a snapshot of a tick it ran was taken); finished_tick: the tick
    whose end decided the outcome (None while running).
    """

    id: int
    world: int
    source: str
    state: TrajectoryState
    reason: AbortReason | None
    detail: str
    joint_names: list[str]
    start_tick: int
    end_tick: int
    duration: float
    tick: int
    progress: float
    feedback_tick: int | None
    desired: list[float]
    actual: list[float]
    error: list[float]
    finished_tick: int | None

    @classmethod
    def started(
        cls, traj_id: int, world: int, spec: JointTrajectorySpec, source: str, start: int, end: int
    ) -> TrajectoryStatus:
        """A trajectory's status when it is accepted: running, nothing sampled yet."""
        return cls(
            id=traj_id,
            world=world,
            source=str(source),
            state=TrajectoryState.RUNNING,
            reason=None,
            detail="",
            joint_names=list(spec.joint_names),
            start_tick=start,
            end_tick=end,
            duration=spec.duration,
            tick=start - 1,
            progress=0.0,
            feedback_tick=None,
            desired=[],
            actual=[],
            error=[],
            finished_tick=None,
        )

    @property
    def done(self) -> bool:
        return self.state is not TrajectoryState.RUNNING

    def as_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["state"] = self.state.value
        out["reason"] = None if self.reason is None else self.reason.value
        return out

    def brief(self) -> dict[str, Any]:
        """The few fields that state frames carry per world."""
        return {
            "id": self.id,
            "state": self.state.value,
            "reason": None if self.reason is None else self.reason.value,
            "progress": self.progress,
        }


@dataclass(frozen=True)
class Resumable:
    """A running trajectory as a recording stores it: enough to sample it on exactly as before.

    target, velocity: the world's target and feed-forward it started from (7 each)."""

    world: int
    spec: JointTrajectorySpec
    start_tick: int
    target: list[float]
    velocity: list[float]

    def as_json(self) -> dict[str, Any]:
        """`resume_from` beside the trajectory's own JSON (what replay reads back)."""
        return {
            **self.spec.to_json(),
            "resume_from": {
                "start_tick": self.start_tick,
                "target": self.target,
                "velocity": self.velocity,
            },
        }


def tolerance_detail(names: list[str], err: np.ndarray, tol: np.ndarray, kind: str) -> str:
    """Which joint broke which tolerance, by how much (the first found); err, tol: (2, 7)
    position and velocity rows of one trajectory."""
    q, j = (int(x) for x in np.argwhere(err > tol)[0])
    what, unit = ("position", "rad") if q == 0 else ("velocity", "rad/s")
    return (
        f"{names[j]}: {kind} tolerance on {what} exceeded "
        f"(error {err[q, j]:.4g} {unit}, tolerance {tol[q, j]:g})"
    )
