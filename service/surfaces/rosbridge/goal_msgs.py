"""The UR driver's actions as rosbridge carries them: goals, feedback and results in their JSON
shape. The names, types, constants and goal rules are the ROS rulebook's (clients/ros_rules.py),
which the ROS node applies to the same goals as rclpy messages.
"""

from __future__ import annotations

from typing import Any

from clients import ros_rules
from clients.ros_rules import ACTIONS, BadMessage, GoalRejected
from service.core.commands.trajectory import (
    JointTolerance,
    JointTrajectorySpec,
    TrajectoryPoint,
    TrajectoryStatus,
)
from service.core.errors import ArmfleetError


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
    sec, nanosec = ros_rules.stamp(t)
    return {"sec": sec, "nanosec": nanosec}


def trajectory_spec(robot: Any, arm: list[str], goal: dict[str, Any]) -> JointTrajectorySpec:
    """A FollowJointTrajectory goal (JSON shape) → a validated spec, or GoalRejected."""
    traj = goal.get("trajectory") or {}
    multi = goal.get("multi_dof_trajectory") or {}
    if multi.get("points") or multi.get("joint_names"):
        raise GoalRejected("multi_dof_trajectory: the UR controllers have no multi-DOF joints")
    names = list(traj.get("joint_names") or [])
    try:
        ros_rules.check_arm_joints(names, arm)
    except BadMessage as exc:
        raise GoalRejected(exc.detail) from None
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

    sec, nanosec = ros_rules.stamp(stamp)
    return {
        "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""},
        "joint_names": s.joint_names,
        "desired": point(s.desired),
        "actual": point(s.actual),
        "error": point(s.error),
    }


def gripper_position(goal: dict[str, Any]) -> float:
    """A GripperCommand goal's finger position [rad], or GoalRejected (the rulebook's checks)."""
    command = goal.get("command")
    if not isinstance(command, dict):
        raise GoalRejected("command: a control_msgs/GripperCommand is required")
    return ros_rules.gripper_goal(command.get("position", 0.0), command.get("max_effort", 0.0))
