"""ROS messages to armfleet commands and back, checked before anything is sent.

A message that cannot be applied whole raises `BadMessage` with a stable `kind` (the counter it
goes to) and a sentence naming the field; nothing of it reaches armfleet, so nothing moves.
armfleet validates again on its side and stays the authority (clamping, trajectory rules): its
refusals come back as their own reasons. Plain Python over message attributes, so it is tested
without ROS.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Sequence
from typing import Any

ARM_JOINTS = 6  # the UR arm's joints come first in armfleet's joint order; finger_joint last


class BadMessage(ValueError):
    """A message that changes nothing; `kind` is its counter, the text says why."""

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(f"{kind}: {detail}")
        self.kind = kind
        self.detail = detail


def _finite(field: str, value: Any) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise BadMessage("not_finite", f"{field} is {v} (must be finite)")
    return v


def joint_state_targets(
    joints: Sequence[str], name: Sequence[str], position: Sequence[float]
) -> dict[str, float]:
    """sensor_msgs/JointState → {joint: target}. Named joints move, the others keep their
    targets; no names = every joint in armfleet's order. Velocity and effort are ignored."""
    if len(position) == 0:
        raise BadMessage("empty", "position is empty; nothing to command")
    if len(name) == 0:
        if len(position) != len(joints):
            raise BadMessage(
                "length_mismatch",
                f"without names, position needs all {len(joints)} joints (got {len(position)})",
            )
        name = joints
    elif len(name) != len(position):
        raise BadMessage(
            "length_mismatch", f"name has {len(name)} entries but position has {len(position)}"
        )
    out: dict[str, float] = {}
    for n, p in zip(name, position, strict=True):
        if n not in joints:
            raise BadMessage("unknown_joint", f"unknown joint {n!r}; joints are {list(joints)}")
        if n in out:
            raise BadMessage("duplicate_joint", f"joint {n!r} named twice")
        out[n] = _finite(f"position of {n}", p)
    return out


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


def stamp(sim_seconds: float) -> tuple[int, int]:
    """Seconds → (sec, nanosec), never negative."""
    ns = max(0, round(sim_seconds * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000


class Counter:
    """Refused messages and goals by kind; each kind logged at most once per second."""

    def __init__(self, logger: Any, interval: float = 1.0) -> None:
        self._logger = logger
        self._interval = interval
        self._lock = threading.Lock()
        self._counts: dict[str, int] = {}
        self._last: dict[str, float] = {}

    def report(self, kind: str, where: str, detail: str) -> None:
        now = time.monotonic()
        with self._lock:
            self._counts[kind] = self._counts.get(kind, 0) + 1
            if now - self._last.get(kind, -math.inf) < self._interval:
                return
            self._last[kind] = now
        self._logger.warning(f"refused on {where}: {kind}: {detail}")

    def counts(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)
