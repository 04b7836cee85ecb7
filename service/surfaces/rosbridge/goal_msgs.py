"""The UR driver's actions as messages: names, types, goal checks, feedback and result shapes.

Everything here works on the ROS messages in their JSON shape (what rosbridge carries).
"""

from __future__ import annotations

import enum
import math
from typing import Any

from service.core.commands.trajectory import (
    JointTolerance,
    JointTrajectorySpec,
    TrajectoryPoint,
    TrajectoryStatus,
)
from service.core.errors import ArmfleetError
from service.surfaces.rosbridge import topics

FJT_TYPE = "control_msgs/action/FollowJointTrajectory"
GRIPPER_TYPE = "control_msgs/action/GripperCommand"
ACTIONS = {
    "scaled_joint_trajectory_controller/follow_joint_trajectory": FJT_TYPE,
    "joint_trajectory_controller/follow_joint_trajectory": FJT_TYPE,
    "robotiq_gripper_controller/gripper_cmd": GRIPPER_TYPE,
}
FEEDBACK_HZ = 20.0  # joint_trajectory_controller's default action_monitor_rate
GOAL_TOLERANCE = 0.01  # rad: GripperActionController's default goal_tolerance
STALL_VELOCITY = 0.01  # rad/s: below this the finger counts as not moving
STALL_TIMEOUT_S = 0.2  # simulated seconds without movement short of the goal: stalled
# control_msgs FollowJointTrajectory result codes
SUCCESSFUL, INVALID_GOAL, INVALID_JOINTS = 0, -1, -2
PATH_TOLERANCE_VIOLATED, GOAL_TOLERANCE_VIOLATED = -4, -5


class Status(enum.IntEnum):
    """action_msgs/GoalStatus values."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6

    @property
    def terminal(self) -> bool:
        return self >= Status.SUCCEEDED


class GoalRejected(ValueError):
    """The goal is invalid; nothing moved. The text says which field and why."""


def action_names(namespaces: dict[str, int]) -> dict[str, tuple[int, str]]:
    """Every action's full name → (world, action type), for each namespace."""
    return {
        f"{ns}/{name}": (w, kind) for ns, w in namespaces.items() for name, kind in ACTIONS.items()
    }


def seconds(value: Any, where: str) -> float:
    """builtin_interfaces Duration/Time JSON (`sec`/`nanosec`, or rosbridge's `secs`/`nsecs`)."""
    if not isinstance(value, dict):
        raise GoalRejected(f"{where}: a duration {{sec, nanosec}} is required")
    sec = value.get("sec", value.get("secs", 0))
    nanosec = value.get("nanosec", value.get("nsecs", 0))
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (sec, nanosec)):
        raise GoalRejected(f"{where}: sec and nanosec must be integers")
    return sec + nanosec * 1e-9


def _duration(t: float) -> dict[str, int]:
    sec, nanosec = topics.stamp(t)
    return {"sec": sec, "nanosec": nanosec}


def trajectory_spec(robot: Any, arm: list[str], goal: dict[str, Any]) -> JointTrajectorySpec:
    """A FollowJointTrajectory goal (JSON shape) → a validated spec, or GoalRejected."""
    traj = goal.get("trajectory") or {}
    multi = goal.get("multi_dof_trajectory") or {}
    if multi.get("points") or multi.get("joint_names"):
        raise GoalRejected("multi_dof_trajectory: the UR controllers have no multi-DOF joints")
    names = list(traj.get("joint_names") or [])
    others = [n for n in names if n not in arm]
    if others:
        raise GoalRejected(
            f"trajectory.joint_names: {others[0]!r} is not a joint of this controller "
            f"(joints: {', '.join(arm)}); the gripper has robotiq_gripper_controller/gripper_cmd"
        )
    points = []
    for i, p in enumerate(traj.get("points") or []):
        if not isinstance(p, dict):
            raise GoalRejected(f"trajectory.points[{i}]: a JointTrajectoryPoint is required")
        points.append(
            TrajectoryPoint(
                positions=list(p.get("positions") or []),
                velocities=list(p.get("velocities") or []),
                accelerations=list(p.get("accelerations") or []),
                time_from_start=seconds(
                    p.get("time_from_start", {}), f"points[{i}].time_from_start"
                ),
            )
        )

    def tolerances(key: str) -> list[JointTolerance]:
        out = []
        for t in goal.get(key) or []:
            out.append(
                JointTolerance(
                    name=t.get("name", ""),
                    position=t.get("position", 0.0),
                    velocity=t.get("velocity", 0.0),
                    acceleration=t.get("acceleration", 0.0),
                )
            )
        return out

    goal_time = seconds(goal.get("goal_time_tolerance", {}), "goal_time_tolerance")
    try:
        return JointTrajectorySpec.build(
            robot,
            names,
            points,
            path_tolerance=tolerances("path_tolerance"),
            goal_tolerance=tolerances("goal_tolerance"),
            goal_time_tolerance=goal_time,
        )
    except ArmfleetError as exc:
        raise GoalRejected(str(exc)) from None


def trajectory_feedback(s: TrajectoryStatus, tick_dt: float) -> dict[str, Any]:
    """FollowJointTrajectory feedback (JSON shape) from a running trajectory's status."""
    assert s.feedback_tick is not None
    stamp = tick_dt * s.feedback_tick
    elapsed = _duration(max(0.0, (s.feedback_tick - s.start_tick + 1) * tick_dt))

    def point(values: list[float]) -> dict[str, Any]:
        return {
            "positions": values,
            "velocities": [],
            "accelerations": [],
            "effort": [],
            "time_from_start": elapsed,
        }

    sec, nanosec = topics.stamp(stamp)
    return {
        "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""},
        "joint_names": s.joint_names,
        "desired": point(s.desired),
        "actual": point(s.actual),
        "error": point(s.error),
    }


def gripper_position(goal: dict[str, Any]) -> float:
    """A GripperCommand goal's finger position [rad], or GoalRejected."""
    command = goal.get("command")
    if not isinstance(command, dict):
        raise GoalRejected("command: a control_msgs/GripperCommand is required")
    position, effort = command.get("position", 0.0), command.get("max_effort", 0.0)
    for value, what in ((position, "position"), (effort, "max_effort")):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise GoalRejected(f"command.{what} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise GoalRejected(f"command.{what} must be finite, got {value}")
    if effort < 0:
        raise GoalRejected(f"command.max_effort must be >= 0, got {effort}")
    return float(position)
