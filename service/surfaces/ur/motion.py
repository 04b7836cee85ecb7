"""What a UR program's commands do to a world, through the core's commands only.

Moves are trajectories (`Control.start_trajectory`): movej as a synchronised joint move
(service.core.kinematics.joint_move, the UR10e's joint speed limits), movel as the core's
`MoveLinear` (a straight TCP line), stops as a deceleration in joint space. Servo and speed
commands are position targets (`Control.command_targets`): servoj's q, speedj/speedl's
velocity integrated into targets by the caller. The TCP offset and the payload are the core's
`SetTcp` and `SetPayload`; forward and inverse kinematics are the served model's
(service.core.kinematics). Why a module of its own: the register decoding (script_commands)
and the URScript lines (urscript) speak of the same motions, and neither touches the core.

Every call names one world and runs on the caller's thread; `Control` is thread-safe.
"""

from __future__ import annotations

import concurrent.futures
from collections.abc import Callable

import numpy as np

from service.core.commands.cartesian import MoveLinear
from service.core.commands.control import Control
from service.core.commands.payload import SetPayload
from service.core.commands.safety_stop import ProtectiveStop
from service.core.commands.tcp import SetTcp
from service.core.commands.trajectory import JointTrajectorySpec, TrajectoryPoint
from service.core.commands.trajectory.status import Started, TrajectoryStatus
from service.core.kinematics.joint_move import JointPlan, plan_joint_move, plan_stop
from service.core.kinematics.tools import ToolTable, tools_of
from service.core.sim.safety import NORMAL
from service.surfaces.ur.rtde_outputs import Frame

ARM = 6
SOURCE = "ur"


class Motion:
    """The motions of every UR world (see the module docstring)."""

    def __init__(self, control: Control, frame: Callable[[], Frame | None]) -> None:
        self.control = control
        self._frame = frame
        self._tools: ToolTable | None = None
        spec = control.spec
        self.names = tuple(spec.names[:ARM])
        self.speed_limits = np.array([j.velocity_limit for j in spec.joints[:ARM]])
        self.effort_limits = np.array([j.effort_limit for j in spec.joints[:ARM]])
        self.lower, self.upper = spec.lower[:ARM].copy(), spec.upper[:ARM].copy()

    @property
    def tools(self) -> ToolTable:
        """The loop's tool table (one per loop: kept once found; Unavailable on an arm with
        no UR kinematics, asked again each time)."""
        if self._tools is None:
            self._tools = tools_of(self.control.loop)
        return self._tools

    # -- reading the world ------------------------------------------------------------------

    def actual(self, world: int) -> tuple[np.ndarray, np.ndarray]:
        """The arm's q and qd (6,) at the latest frame."""
        frame = self._frame()
        if frame is None:
            q = self.targets(world)
            return q, np.zeros(ARM)
        snap = frame.snap
        return (
            np.asarray(snap.position[world, :ARM], np.float64),
            np.asarray(snap.velocity[world, :ARM], np.float64),
        )

    def targets(self, world: int) -> np.ndarray:
        return self.control.loop.commands.pending_targets(world)[:ARM].astype(np.float64)

    def tcp(self, world: int) -> np.ndarray:
        return self.tools.get(world)

    def fk(self, q: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        return self.tools.kin.fk(np.asarray(q, np.float64)[None], np.asarray(tcp)[None])[0]

    def ik(self, pose: np.ndarray, q_near: np.ndarray, tcp: np.ndarray) -> np.ndarray | None:
        got = self.tools.kin.ik(np.asarray(pose)[None], np.asarray(q_near)[None], tcp[None])
        return got.q[0] if got.ok[0] else None

    def running(self, world: int) -> TrajectoryStatus | None:
        status = self.control.trajectories.status(world)
        return status if status is not None and status.state == "running" else None

    # -- moving it --------------------------------------------------------------------------

    def _run(self, world: int, plan: JointPlan) -> Started:
        points = [
            TrajectoryPoint(p.tolist(), float(t), v.tolist())
            for t, p, v in zip(plan.times, plan.q, plan.qd, strict=True)
        ]
        spec = JointTrajectorySpec.build(self.control.spec, self.names, points)
        return self.control.start_trajectory([world], spec, SOURCE)[0]

    def move_joints(self, world: int, goal: np.ndarray, speed: float, accel: float) -> Started:
        """movej from the world's current targets (BadCommand before anything moves)."""
        plan = plan_joint_move(
            self.targets(world), goal, speed, accel, self.speed_limits,
            self.lower, self.upper, self.names,
        )  # fmt: skip
        return self._run(world, plan)

    def move_linear(self, world: int, pose: np.ndarray, speed: float, accel: float) -> Started:
        """movel of the world's TCP (BadCommand before anything moves)."""
        cmd = MoveLinear.line(self.control, world, list(map(float, pose)), speed, accel)
        return self.control.run(cmd, SOURCE)[0]

    def wait(self, started: Started) -> concurrent.futures.Future[TrajectoryStatus]:
        return self.control.trajectories.wait(started.id)

    def servo(self, world: int, q: np.ndarray) -> None:
        """Arm targets q (6,) at once (servoj; a running trajectory is stopped by it)."""
        q = np.clip(np.asarray(q, np.float64), self.lower, self.upper)
        self.control.command_targets(world, list(self.names), q.tolist(), SOURCE)

    def stop(self, world: int, decel: float) -> Started | None:
        """Decelerate from the arm's actual motion to rest (stopj/stopl, speedStop, servoStop)."""
        q, qd = self.actual(world)
        self.control.cancel_trajectory([world], SOURCE)
        if np.abs(qd).max() < 1e-4:
            self.servo(world, self.targets(world))
            return None
        return self._run(world, plan_stop(q, qd, max(decel, 0.1), self.lower, self.upper))

    def halt(self, world: int) -> None:
        """Hold the arm where it is now (a program that ends while it moves). A protective-
        stopped world is held already (by the stop itself) and takes no targets."""
        if self.control.loop.safety.mode(world) != NORMAL:
            return
        q, _ = self.actual(world)
        self.control.cancel_trajectory([world], SOURCE)
        self.servo(world, q)

    def protective_stop(self, world: int, why: str) -> None:
        """Hold the arm where it is now and protective-stop the world, in one step (the core's
        `ProtectiveStop` command)."""
        q, _ = self.actual(world)
        self.control.run(ProtectiveStop.create(self.control, world, q, why), SOURCE)

    def set_tcp(self, world: int, pose: list[float]) -> None:
        self.control.run(SetTcp.create(self.control, world, pose), SOURCE)

    def set_payload(self, world: int, mass: float, cog: list[float]) -> None:
        item = {"world": world, "mass": mass, "cog": cog}
        self.control.run(SetPayload.create(self.control, [item]), SOURCE)
