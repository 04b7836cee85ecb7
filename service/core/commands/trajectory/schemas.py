"""The HTTP and WebSocket shapes of trajectories: pydantic models, so OpenAPI states them.

The request is trajectory_msgs/JointTrajectory plus the tolerances of a FollowJointTrajectory
goal. The schema states what JSON Schema can (joint names, distinct names, lengths per point,
finite numbers, the limits on points and seconds); what it cannot (times strictly increasing,
each position inside its own joint's limits, velocities on every point or none) is checked by
`spec.parse` and refused with 422 naming the field and the limit, before anything changes.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, Field

from service.core.commands.fields import (
    FiniteFloat,
    LazyJsonSchema,
    Strict,
    WorldId,
    bounded_float,
    example_config,
    joint_names,
    json_int,
)
from service.core.commands.trajectory.spec import MAX_DURATION_S, MAX_POINTS
from service.core.sim.types import NJOINT
from service.core.sim.worlds import WORLDS_PATTERN

_N = NJOINT
Number = FiniteFloat
Seconds = bounded_float(0, MAX_DURATION_S, f"seconds, 0..{MAX_DURATION_S:g}")
# The names come from the model when the document is built (importing compiles nothing).
JointName = Annotated[str, LazyJsonSchema(lambda: {"type": "string", "enum": list(joint_names())})]
_Strict = Strict


class Duration(_Strict):
    """builtin_interfaces/Duration, as rosbridge and ROS tools write it."""

    sec: json_int(0, int(MAX_DURATION_S))  # type: ignore[valid-type]
    nanosec: json_int(0, 999_999_999) = 0  # type: ignore[valid-type]


class TrajectoryPointBody(_Strict):
    """trajectory_msgs/JointTrajectoryPoint: values in the order of `joint_names`."""

    positions: list[Number] = Field(min_length=1, max_length=_N, description="rad")
    velocities: list[Number] = Field(
        default=[], max_length=_N, description="rad/s; all points or none (then: linear)"
    )
    accelerations: list[Number] = Field(
        default=[], max_length=_N, description="rad/s²; with velocities: quintic, else cubic"
    )
    time_from_start: Seconds | Duration = Field(
        description="after the start tick; strictly increasing from point to point"
    )


class JointToleranceBody(_Strict):
    """control_msgs/JointTolerance: > 0 checks the bound; 0 or -1 does not."""

    name: JointName = Field(
        description="a joint that `joint_names` lists (one field against another, which JSON "
        "Schema cannot state: any other joint is refused with 422)"
    )
    position: Number = Field(default=0.0, description="rad")
    velocity: Number = Field(default=0.0, description="rad/s")
    acceleration: Number = Field(default=0.0, description="accepted, not checked")


class TrajectoryBody(_Strict):
    """A JointTrajectory to follow, with FollowJointTrajectory's optional tolerances."""

    joint_names: list[JointName] = Field(
        min_length=1, max_length=_N, json_schema_extra={"uniqueItems": True}
    )
    points: list[TrajectoryPointBody] = Field(
        min_length=1, max_length=MAX_POINTS, description=f"at most {MAX_POINTS}"
    )
    path_tolerance: list[JointToleranceBody] = Field(default=[], max_length=_N)
    goal_tolerance: list[JointToleranceBody] = Field(default=[], max_length=_N)
    goal_time_tolerance: Seconds | Duration = 0.0

    model_config = example_config(
        {
            "joint_names": ["shoulder_pan_joint", "elbow_joint"],
            "points": [
                {"positions": [0.5, 1.2], "time_from_start": 1.0},
                {"positions": [0.0, 1.57], "time_from_start": 2.0},
            ],
        }
    )

    def as_json(self) -> dict[str, Any]:
        """The plain dict `spec.parse` reads."""
        return self.model_dump()


class BatchTrajectoryBody(_Strict):
    """One trajectory for many worlds, started at the same tick."""

    model_config = example_config(
        {
            "worlds": "0-3",
            "trajectory": {
                "joint_names": ["elbow_joint"],
                "points": [{"positions": [1.2], "time_from_start": 2.0}],
            },
        }
    )

    worlds: (
        Annotated[list[WorldId], Field(min_length=1, json_schema_extra={"uniqueItems": True})]
        | Annotated[str, Field(pattern=WORLDS_PATTERN)]
    ) = Field(
        description="distinct world ids, or ids and ranges like 0-9999",
        examples=["0-3"],
    )
    trajectory: TrajectoryBody


class StartedReply(BaseModel):
    id: int = Field(description="the trajectory's id (GET and DELETE name the world)")
    world: int
    start_tick: int = Field(description="the first tick stepped with it")
    end_tick: int = Field(description="the tick at whose end its last point is reached")


class BatchStartedReply(BaseModel):
    start_tick: int
    end_tick: int
    started: int = Field(description="how many worlds it started on")
    ids: list[int] = Field(description="trajectory ids, in the order of `worlds`")
    worlds: list[int]


class TrajectoryStatusReply(BaseModel):
    """Status, progress and feedback of a world's current (or last) trajectory."""

    id: int
    world: int
    source: str = Field(description="http, ws, browser, ros2, rosbridge, replay")
    state: str = Field(description="running, succeeded or aborted")
    reason: str | None = Field(
        description="when aborted: path_tolerance, goal_tolerance, preempted, manual_override, "
        "reset, fault or cancelled"
    )
    detail: str
    joint_names: list[str]
    start_tick: int
    end_tick: int
    duration: float = Field(description="seconds")
    tick: int = Field(description="the last tick sampled")
    progress: float = Field(description="0..1 of the duration, at `tick`")
    feedback_tick: int | None = Field(description="tick of desired/actual/error")
    desired: list[float]
    actual: list[float]
    error: list[float] = Field(description="actual - desired [rad], per joint of joint_names")
    finished_tick: int | None
