"""A validated JointTrajectory: what a world is asked to follow, checked before anything changes.

The shape is trajectory_msgs/JointTrajectory plus the tolerances of a
control_msgs/FollowJointTrajectory goal, so that every surface (HTTP, WebSocket, ROS 2 actions,
rosbridge) converts its message into the same `JointTrajectorySpec` and gets the same errors.
Validation raises `BadCommand` naming the field (``points[2].positions[1]``) and the limit that
was broken; a spec that exists is valid for the robot it was built against.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from service.core.errors import BadCommand
from service.core.sim.types import RobotSpec

MAX_POINTS = 1000  # points per trajectory; MoveIt plans rarely have more than a few hundred
MAX_DURATION_S = 3600.0  # time_from_start of the last point, and goal_time_tolerance [s]


@dataclass(frozen=True)
class TrajectoryPoint:
    """One trajectory_msgs/JointTrajectoryPoint: values in the order of `joint_names`.

    velocities and accelerations are empty when not given (as in the ROS message).
    time_from_start: seconds after the trajectory's start tick.
    """

    positions: Sequence[float]
    time_from_start: float
    velocities: Sequence[float] = ()
    accelerations: Sequence[float] = ()


@dataclass(frozen=True)
class JointTolerance:
    """control_msgs/JointTolerance: > 0 checks the bound, 0 or -1 does not (as in ros2_controllers).

    Position [rad] and velocity [rad/s] are checked; acceleration is accepted and not checked
    (the engine does not report joint accelerations).
    """

    name: str
    position: float = 0.0
    velocity: float = 0.0
    acceleration: float = 0.0


@dataclass(frozen=True)
class JointTrajectorySpec:
    """A trajectory over a subset of the seven commanded joints, valid for one RobotSpec.

    joint_names: the joints it moves, in the order of the point values (no repeats)
    joints: their indices in command order (six arm joints, then finger_joint)     (k,) int64
    times: time_from_start of every point [s], strictly increasing, >= 0           (P,)
    positions: [rad]                                                             (P, k)
    velocities: [rad/s] or None when the points carry none (then: linear)          (P, k)
    accelerations: [rad/s²] or None (with velocities: cubic; with both: quintic)   (P, k)
    path_position, path_velocity, goal_position, goal_velocity: per joint of `joints`,
        +inf where not checked                                                      (k,)
    goal_time_tolerance: how long after the end the goal tolerance may still be met [s]

    Build one with `JointTrajectorySpec.build` (dataclasses) or `parse` (a JSON-shaped body);
    `to_json` gives the body back (recordings store it, replay parses it again).
    """

    joint_names: tuple[str, ...]
    joints: np.ndarray
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None
    accelerations: np.ndarray | None
    path_position: np.ndarray
    path_velocity: np.ndarray
    goal_position: np.ndarray
    goal_velocity: np.ndarray
    goal_time_tolerance: float = 0.0
    order: int = field(init=False)

    def __post_init__(self) -> None:
        # 1: linear (positions only), 3: cubic (with velocities), 5: quintic (with accelerations)
        order = 1 if self.velocities is None else 3 if self.accelerations is None else 5
        object.__setattr__(self, "order", order)

    @property
    def duration(self) -> float:
        """time_from_start of the last point [s]."""
        return float(self.times[-1])

    @property
    def has_path_tolerance(self) -> bool:
        return bool(np.isfinite(self.path_position).any() or np.isfinite(self.path_velocity).any())

    @property
    def has_goal_tolerance(self) -> bool:
        return bool(np.isfinite(self.goal_position).any() or np.isfinite(self.goal_velocity).any())

    @classmethod
    def build(
        cls,
        robot: RobotSpec,
        joint_names: Sequence[str],
        points: Sequence[TrajectoryPoint],
        path_tolerance: Sequence[JointTolerance] = (),
        goal_tolerance: Sequence[JointTolerance] = (),
        goal_time_tolerance: float = 0.0,
    ) -> JointTrajectorySpec:
        """Validate everything, then build; BadCommand names the first field that is wrong."""
        names, joints = _check_names(robot, joint_names)
        k = len(names)
        if not points:
            raise BadCommand("points", "a trajectory needs at least one point")
        if len(points) > MAX_POINTS:
            raise BadCommand("points", f"{len(points)} points; at most {MAX_POINTS} are allowed")
        has_vel = len(points[0].velocities) > 0
        has_acc = len(points[0].accelerations) > 0
        pos = np.empty((len(points), k))
        vel = np.empty((len(points), k)) if has_vel else None
        acc = np.empty((len(points), k)) if has_acc else None
        times = np.empty(len(points))
        for i, p in enumerate(points):
            where = f"points[{i}]"
            pos[i] = _values(p.positions, k, f"{where}.positions")
            if (len(p.velocities) > 0) != has_vel:
                raise BadCommand(f"{where}.velocities", "give velocities for every point or none")
            if (len(p.accelerations) > 0) != has_acc:
                raise BadCommand(
                    f"{where}.accelerations", "give accelerations for every point or none"
                )
            if vel is not None:
                vel[i] = _values(p.velocities, k, f"{where}.velocities")
            if acc is not None:
                acc[i] = _values(p.accelerations, k, f"{where}.accelerations")
            times[i] = _time(p.time_from_start, i, times[i - 1] if i else None)
        if has_acc and not has_vel:
            raise BadCommand("points[0].velocities", "accelerations need velocities as well")
        _check_limits(robot, joints, pos)
        path_p, path_v = _tolerances(robot, names, path_tolerance, "path_tolerance")
        goal_p, goal_v = _tolerances(robot, names, goal_tolerance, "goal_tolerance")
        gtt = _seconds(goal_time_tolerance, "goal_time_tolerance")
        for arr in (joints, times, pos, vel, acc, path_p, path_v, goal_p, goal_v):
            if arr is not None:
                arr.flags.writeable = False
        return cls(names, joints, times, pos, vel, acc, path_p, path_v, goal_p, goal_v, gtt)

    def to_json(self) -> dict[str, Any]:
        """The JSON body this spec parses from (time_from_start in seconds)."""
        points = []
        for i, t in enumerate(self.times):
            p: dict[str, Any] = {"positions": self.positions[i].tolist(), "time_from_start": t}
            if self.velocities is not None:
                p["velocities"] = self.velocities[i].tolist()
            if self.accelerations is not None:
                p["accelerations"] = self.accelerations[i].tolist()
            points.append(p)
        return {
            "joint_names": list(self.joint_names),
            "points": points,
            "path_tolerance": _tol_json(self.joint_names, self.path_position, self.path_velocity),
            "goal_tolerance": _tol_json(self.joint_names, self.goal_position, self.goal_velocity),
            "goal_time_tolerance": self.goal_time_tolerance,
        }


def parse(robot: RobotSpec, body: Mapping[str, Any]) -> JointTrajectorySpec:
    """A spec from a JSON-shaped JointTrajectory (+ tolerances); BadCommand on any bad field.

    time_from_start and goal_time_tolerance are seconds, or {"sec": s, "nanosec": ns} as in ROS.
    """
    points = [
        TrajectoryPoint(
            positions=p.get("positions") or (),
            velocities=p.get("velocities") or (),
            accelerations=p.get("accelerations") or (),
            time_from_start=duration_seconds(
                p.get("time_from_start"), f"points[{i}].time_from_start"
            ),
        )
        for i, p in enumerate(body.get("points") or ())
    ]
    tols = {
        key: [JointTolerance(**t) for t in body.get(key) or ()]
        for key in ("path_tolerance", "goal_tolerance")
    }
    gtt = duration_seconds(body.get("goal_time_tolerance", 0.0), "goal_time_tolerance")
    return JointTrajectorySpec.build(
        robot, body.get("joint_names") or (), points, goal_time_tolerance=gtt, **tols
    )


def duration_seconds(value: Any, where: str) -> float:
    """Seconds from a number or a builtin_interfaces/Duration-shaped {"sec", "nanosec"}."""
    if isinstance(value, Mapping):
        value = float(value.get("sec", 0)) + float(value.get("nanosec", 0)) * 1e-9
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadCommand(where, f"must be a number of seconds, got {value!r}")
    return float(value)


def _check_names(
    robot: RobotSpec, joint_names: Sequence[str]
) -> tuple[tuple[str, ...], np.ndarray]:
    if not joint_names:
        raise BadCommand("joint_names", f"name at least one joint of {robot.names}")
    seen: set[str] = set()
    idx = []
    for i, name in enumerate(joint_names):
        if name not in robot.names:
            raise BadCommand(
                f"joint_names[{i}]", f"unknown joint {name!r}; joints are {robot.names}"
            )
        if name in seen:
            raise BadCommand(f"joint_names[{i}]", f"joint {name!r} is named twice")
        seen.add(name)
        idx.append(robot.names.index(name))
    return tuple(joint_names), np.array(idx, dtype=np.int64)


def _values(values: Sequence[float], k: int, where: str) -> np.ndarray:
    if len(values) != k:
        raise BadCommand(where, f"has {len(values)} values; joint_names has {k}")
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise BadCommand(where, "values must be numbers") from None
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise BadCommand(f"{where}[{bad[0]}]", "values must be finite (no NaN or Inf)")
    return arr


def _seconds(value: float, where: str) -> float:
    if not math.isfinite(value) or value < 0:
        raise BadCommand(where, f"must be finite and >= 0 s, got {value}")
    if value > MAX_DURATION_S:
        raise BadCommand(where, f"{value} s is longer than the limit of {MAX_DURATION_S:g} s")
    return float(value)


def _time(value: float, i: int, previous: float | None) -> float:
    where = f"points[{i}].time_from_start"
    t = _seconds(value, where)
    if previous is not None and t <= previous:
        raise BadCommand(where, f"times must increase: {t} s after {previous} s")
    return t


def _check_limits(robot: RobotSpec, joints: np.ndarray, pos: np.ndarray) -> None:
    lower, upper = robot.lower[joints], robot.upper[joints]
    bad = np.argwhere((pos < lower) | (pos > upper))
    if bad.size:
        i, j = (int(x) for x in bad[0])
        name = robot.names[joints[j]]
        raise BadCommand(
            f"points[{i}].positions[{j}]",
            f"{pos[i, j]} rad is outside {name}'s limits [{lower[j]:.6g}, {upper[j]:.6g}]",
        )


def _tolerances(
    robot: RobotSpec, names: tuple[str, ...], tols: Sequence[JointTolerance], key: str
) -> tuple[np.ndarray, np.ndarray]:
    pos = np.full(len(names), np.inf)
    vel = np.full(len(names), np.inf)
    for i, tol in enumerate(tols):
        if tol.name not in names:
            raise BadCommand(
                f"{key}[{i}].name", f"{tol.name!r} is not in joint_names {list(names)}"
            )
        j = names.index(tol.name)
        for what, value, out in (("position", tol.position, pos), ("velocity", tol.velocity, vel)):
            number = isinstance(value, int | float) and not isinstance(value, bool)
            if not number or not math.isfinite(value):
                raise BadCommand(f"{key}[{i}].{what}", f"must be a finite number, got {value!r}")
            if value > 0:
                out[j] = float(value)
    return pos, vel


def _tol_json(names: tuple[str, ...], pos: np.ndarray, vel: np.ndarray) -> list[dict[str, Any]]:
    return [
        {
            "name": n,
            "position": float(p) if math.isfinite(p) else 0.0,
            "velocity": float(v) if math.isfinite(v) else 0.0,
        }
        for n, p, v in zip(names, pos, vel, strict=True)
        if math.isfinite(p) or math.isfinite(v)
    ]
