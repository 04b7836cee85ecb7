"""ROS messages to armfleet commands, checked before anything is sent.

A message that cannot be applied whole raises `BadMessage` with a stable `kind` (the counter it
goes to) and a sentence naming the field; nothing of it reaches armfleet, so nothing moves. The
JointState rule, `BadMessage` and the rest that rosbridge shares are the ROS rulebook's
(clients/ros_rules.py); what only this node takes (forward_position_controller's arrays,
JointTrajectory on a topic) is here.

armfleet validates again on its side and stays the authority (clamping, trajectory rules): its
refusals come back as their own reasons. Plain Python over message attributes, so it is tested
without ROS.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from clients import ros_rules
from clients.ros_rules import ARM_JOINTS, BadMessage


def _finite(field: str, value: Any) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise BadMessage("not_finite", f"{field} is {v} (must be finite)")
    return v


def joint_state_targets(joints: Sequence[str], name: Any, position: Any) -> dict[str, float]:
    """sensor_msgs/JointState → {joint: target}, by the JointState rule of every armfleet
    surface (clients/ros_rules.py: rosbridge answers a bad message in the same words). Named
    joints move, the others keep their targets; no names = every joint in armfleet's order.
    Velocity and effort are ignored."""
    targets = ros_rules.joint_state(joints, list(name), list(position))
    return {joints[i]: v for i, v in targets.items()}


def forward_targets(joints: Sequence[str], data: Sequence[float]) -> dict[str, float]:
    """std_msgs/Float64MultiArray of forward_position_controller → the six arm joints."""
    arm = list(joints)[:ARM_JOINTS]
    if len(data) != len(arm):
        raise BadMessage("length_mismatch", f"data needs the {len(arm)} arm joints {arm}")
    return {n: _finite(f"data[{i}]", v) for i, (n, v) in enumerate(zip(arm, data, strict=True))}


def seconds(duration: Any) -> float:
    """builtin_interfaces/Duration → seconds."""
    return float(duration.sec) + float(duration.nanosec) * 1e-9


def trajectory_body(traj: Any, path_tol: Any = (), goal_tol: Any = (), goal_time: Any = None):
    """trajectory_msgs/JointTrajectory (+ FollowJointTrajectory tolerances) → the JSON body of
    `POST /v1/worlds/{w}/trajectory`. Shapes, times and limits are armfleet's to judge."""
    names = list(traj.joint_names)
    points = []
    for i, p in enumerate(traj.points):
        points.append(
            {
                "positions": [_finite(f"points[{i}].positions", v) for v in p.positions],
                "velocities": [_finite(f"points[{i}].velocities", v) for v in p.velocities],
                "accelerations": [
                    _finite(f"points[{i}].accelerations", v) for v in p.accelerations
                ],
                "time_from_start": seconds(p.time_from_start),
            }
        )

    def tol(items: Any) -> list[dict[str, Any]]:
        return [
            {"name": t.name, "position": float(t.position), "velocity": float(t.velocity)}
            for t in items
        ]

    return {
        "joint_names": names,
        "points": points,
        "path_tolerance": tol(path_tol),
        "goal_tolerance": tol(goal_tol),
        "goal_time_tolerance": 0.0 if goal_time is None else seconds(goal_time),
    }
