"""What a trajectory's owner is told: ids and ticks when it starts, status and outcome after.

Plain frozen dataclasses so that every surface (HTTP, WebSocket, ROS 2 actions, rosbridge)
serialises the same facts; `as_json` is the HTTP/WebSocket shape.
"""

from __future__ import annotations

import enum
from dataclasses import asdict, dataclass
from typing import Any


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
    MANUAL_OVERRIDE = "manual_override"  # a target command (button, set targets) took over
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
