"""Cartesian commands: a TCP pose target (`tcp_target`), a pendant's jog step (`jog`) and a
straight line at a given speed (`move_linear`, UR's moveL), on one world.

Poses are UR's p[x, y, z, rx, ry, rz] in the robot's base frame, of the world's TCP (its
`set_tcp` offset; the flange until set); service.core.kinematics says the frames. Each command
starts from the world's current *targets* (so repeated jogs add up exactly, as Up/Down does),
solves the closed-form IK nearest them, and refuses a pose no configuration reaches with a 422
naming the field, before anything moves. The arm's six joints are commanded; the gripper keeps
its target.

- `tcp_target` and `jog` set the six arm targets at once (the servos get there on their own,
  in joint space) and replay as those rows; a jog refuses a step that would swing a joint by
  more than `JOG_SWING` (a configuration flip at a singularity).
- `move_linear` is a trajectory (service.core.commands.trajectory): the line sampled into joint
  points with velocities (service.core.kinematics.line), followed with velocity feed-forward,
  watched and cancelled like any trajectory, recorded and replayed as one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import Field

from service.core.commands.base import Door
from service.core.commands.fields import FiniteFloat, Strict, bounded_float, example_config
from service.core.commands.targets import _model, _OneWorld
from service.core.commands.tcp import POSE_REACH, pose_field, pose_values
from service.core.commands.trajectory.commands import StartTrajectory
from service.core.commands.trajectory.spec import JointTrajectorySpec, TrajectoryPoint
from service.core.errors import BadCommand
from service.core.kinematics.line import plan_line
from service.core.kinematics.pose import matrix_to_pose, rotvec_to_matrix
from service.core.kinematics.tools import tools_of
from service.core.sim import arithmetic, rules
from service.core.sim.types import RobotSpec

__all__ = ["Jog", "JogStep", "LinearMove", "MoveLinear", "MoveTcp", "TcpPose"]

ARM = 6  # the arm's joints are the first six commanded joints
JOG_STEP = 0.1  # m or rad: the largest jog step
JOG_SWING = 0.5  # rad: the most a jog step may turn one joint
SPEED = (1e-3, 3.0)  # m/s (rad/s for a pure rotation): moveL's speed
ACCEL = (1e-3, 150.0)  # m/s² (rad/s²)
AXES = ("x", "y", "z", "rx", "ry", "rz")

POSE = pose_field(POSE_REACH, "TCP pose in the base frame", [-0.69, -0.17, 0.5, 2.22, 2.22, 0])


class TcpPose(Strict):
    """Where the TCP should go: joint targets from the IK nearest the current ones."""

    pose: list[FiniteFloat] = POSE

    model_config = example_config({"pose": [-0.69, -0.17, 0.5, 2.22, 2.22, 0]})


class JogStep(Strict):
    """One pendant step: along (x, y, z, m) or about (rx, ry, rz, rad) an axis of the base or
    the tool frame."""

    axis: Literal["x", "y", "z", "rx", "ry", "rz"]
    step: FiniteFloat = Field(
        ge=-JOG_STEP, le=JOG_STEP, description=f"m or rad, within ±{JOG_STEP:g}; the sign is ±"
    )
    frame: Literal["base", "tool"] = "base"

    model_config = example_config({"axis": "z", "step": 0.01, "frame": "tool"})


class LinearMove(Strict):
    """UR's moveL: the TCP on a straight line to `pose`, at `speed` with `accel`."""

    pose: list[FiniteFloat] = POSE
    speed: bounded_float(*SPEED, "m/s (rad/s for a pure rotation); UR's default 0.25") = 0.25  # type: ignore[valid-type]
    accel: bounded_float(*ACCEL, "m/s² (rad/s²); UR's default 1.2") = 1.2  # type: ignore[valid-type]

    model_config = example_config({"pose": [-0.69, -0.17, 0.4, 2.22, 2.22, 0], "speed": 0.25})


def _start(door: Door, world: int) -> tuple[np.ndarray, np.ndarray]:
    """The world's current arm targets (6,) and TCP offset (6,)."""
    return door.loop.commands.pending_targets(world)[:ARM], tools_of(door.loop).get(world)


def _solve(door: Door, world: int, pose: np.ndarray, field: str) -> dict[int, float]:
    """Arm targets for `pose` nearest the current ones, as joint index → value."""
    q, tcp = _start(door, world)
    got = tools_of(door.loop).kin.ik(pose[None], q[None], tcp[None])
    if not got.ok[0]:
        raise BadCommand(field, f"no joint configuration reaches the pose ({got.why(0)})")
    return dict(enumerate(got.q[0].tolist()))


@dataclass(frozen=True)
class _ArmTargets(_OneWorld):
    """Arm targets a Cartesian command solved for (`values`), replayed as their rows."""

    def update(self, spec: RobotSpec, row: np.ndarray) -> arithmetic.TargetUpdate:
        return arithmetic.replace_targets(spec, row, self.values)


@dataclass(frozen=True)
class MoveTcp(_ArmTargets, kind="tcp_target", op="tcp_target", http=("tcp_target",)):
    """Set the arm's targets so that the TCP reaches `pose` (base frame)."""

    @classmethod
    def create(cls, door: Door, world: object, pose: Any) -> MoveTcp:
        world = rules.world_id(world, door.nworld)
        return cls(world, _solve(door, world, pose_values(pose, "pose", POSE_REACH), "pose"))

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> MoveTcp:
        return cls.create(door, world, _model(TcpPose, body).pose)


@dataclass(frozen=True)
class Jog(_ArmTargets, kind="jog", op="jog", http=("jog",)):
    """Move the TCP one step along or about an axis of the base or the tool frame (the
    rotation turns about the TCP itself), from the pose of the current targets."""

    @classmethod
    def create(cls, door: Door, world: object, axis: Any, step: Any, frame: Any = "base") -> Jog:
        world = rules.world_id(world, door.nworld)
        if axis not in AXES:
            raise BadCommand("axis", f"must be one of {list(AXES)}, got {axis!r}")
        if frame not in ("base", "tool"):
            raise BadCommand("frame", f"must be 'base' or 'tool', got {frame!r}")
        number = isinstance(step, int | float) and not isinstance(step, bool)
        if not number or not math.isfinite(step) or abs(step) > JOG_STEP:
            raise BadCommand("step", f"must be a number within ±{JOG_STEP:g} (m or rad)")
        q, tcp = _start(door, world)
        kin = tools_of(door.loop).kin
        now = kin.tcp(q[None], tcp[None])[0]
        move = np.eye(4)
        k = AXES.index(axis)
        if k < 3:
            move[k, 3] = step
        else:
            move[:3, :3] = rotvec_to_matrix(np.eye(3)[k - 3] * step)
        if frame == "tool":
            goal = now @ move
        else:  # base axes, turning about the TCP
            goal = move.copy()
            goal[:3, :3] = move[:3, :3] @ now[:3, :3]
            goal[:3, 3] = now[:3, 3] + move[:3, 3]
        got = kin.ik(matrix_to_pose(goal)[None], q[None], tcp[None])
        if not got.ok[0]:
            raise BadCommand("step", f"the step leaves the arm's reach ({got.why(0)})")
        swing = np.abs(got.q[0] - q)
        if swing.max() > JOG_SWING:
            j = int(np.argmax(swing))
            raise BadCommand(
                "step",
                f"the step would turn {door.spec.names[j]} by {swing[j]:.3g} rad (more than "
                f"{JOG_SWING:g}): the arm is at a singularity; move it away in joint space",
            )
        return cls(world, dict(enumerate(got.q[0].tolist())))

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> Jog:
        req = _model(JogStep, body)
        return cls.create(door, world, req.axis, req.step, req.frame)


@dataclass(frozen=True)
class MoveLinear(StartTrajectory, kind="move_linear", op="move_linear", http=("move_linear",)):
    """A straight TCP line to `pose` (UR's moveL): a trajectory of the arm's joints."""

    @classmethod
    def line(
        cls, door: Door, world: object, pose: Any, speed: Any = 0.25, accel: Any = 1.2
    ) -> MoveLinear:
        """The line from the world's current targets; 422 naming pose, speed or accel."""
        world = rules.world_id(world, door.nworld)
        goal = pose_values(pose, "pose", POSE_REACH)
        v = _bounded(speed, "speed", SPEED, "m/s")
        a = _bounded(accel, "accel", ACCEL, "m/s²")
        q, tcp = _start(door, world)
        spec = door.spec
        limits = np.array([j.velocity_limit for j in spec.joints[:ARM]])
        names = tuple(spec.names[:ARM])
        tools = tools_of(door.loop)
        tick = door.loop.batch.tick_dt  # samples on the loop's ticks (kinematics/line.py)
        plan = plan_line(tools.kin, q, goal, tcp, v, a, limits, names, tools.lag, tick)
        points = [
            TrajectoryPoint(p.tolist(), float(t), v_.tolist())
            for t, p, v_ in zip(plan.times, plan.q, plan.qd, strict=True)
        ]
        return cls([world], JointTrajectorySpec.build(spec, names, points))

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> MoveLinear:
        req = _model(LinearMove, body)
        return cls.line(door, world, req.pose, req.speed, req.accel)

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> StartTrajectory:
        """Replayed as the trajectory it became (its samples, exactly)."""
        return StartTrajectory.from_record(door, rec)


def _bounded(value: Any, field: str, bounds: tuple[float, float], unit: str) -> float:
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if not number or not math.isfinite(value) or not bounds[0] <= value <= bounds[1]:
        raise BadCommand(field, f"must be a number in {bounds[0]:g}..{bounds[1]:g} {unit}")
    return float(value)
