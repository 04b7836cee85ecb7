"""One line of URScript on a script port, carried out: the small set `urscript.SIGNATURES` has.

A line is a program of one call, as on the robot: it replaces whatever program ran (ur_rtde's
control script included) and starts at once; a move preempts the move before it.
- movej(q | p[...], a=1.4, v=1.05, t=0, r=0): a joint move (a pose is solved nearest the
  current targets); t > 0 sets the duration (v is chosen to take t), r is ignored (no blend
  with one move).
- movel(p[...] | q, a=1.2, v=0.25, t=0, r=0): a straight TCP line.
- servoj(q, ...): the arm's targets at once.
- speedj(qd, a, t) / speedl(xd, a, t): that velocity for t seconds, then a stop at a
  (t = 0: until the next line).
- stopj(a) / stopl(a): decelerate to rest.
- set_tcp(p[...]), set_payload(m, cog): the world's TCP offset and payload.
A value the robot would not take (out of range, a pose out of reach) is refused with the
reason (`Refused`), and nothing moves.
"""

from __future__ import annotations

import asyncio
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from service.core.errors import BadCommand, ProtectiveStopped
from service.surfaces.ur import urscript
from service.surfaces.ur.speed import SpeedLoop

if TYPE_CHECKING:
    from service.surfaces.ur.world_robot import WorldRobot

PERIOD_S = 0.008


class Refused(ValueError):
    """A line armfleet does not carry out; the text names the function and why."""


def speed_for(distance: float, accel: float, seconds: float) -> float:
    """The cruise speed with which `line.profile` covers `distance` in `seconds` at `accel`."""
    k = math.pi / (2 * accel)
    disc = seconds * seconds - 4 * k * distance
    if disc < 0:
        raise Refused(f"t={seconds:g} s is too short for this move at a={accel:g}")
    return max((seconds - math.sqrt(disc)) / (2 * k), 1e-3)


class LineSpeed:
    """A speedj/speedl line's velocity, held on a timer for its time (one per world)."""

    def __init__(self, robot: WorldRobot) -> None:
        self.robot = robot
        self.loop = SpeedLoop(robot.motion, robot.world)
        self.left = 0.0
        self.timer: asyncio.TimerHandle | None = None

    def start(self, kind: str, speed: list[float], accel: float, seconds: float) -> None:
        self.loop.begin(kind, speed, accel)
        self.left, self.accel = (seconds if seconds > 0 else math.inf), accel
        if self.timer is None:
            self.timer = asyncio.get_running_loop().call_later(PERIOD_S, self._tick)

    def end(self) -> None:
        self.loop.end()
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None

    def _tick(self) -> None:
        self.timer = None
        self.left -= PERIOD_S
        try:
            self.loop.step(PERIOD_S)
        except (BadCommand, ProtectiveStopped):
            return self.end()
        if self.left <= 0:
            self.end()
            self.robot.motion.stop(self.robot.world, self.accel)
            return
        self.timer = asyncio.get_running_loop().call_later(PERIOD_S, self._tick)


def line_speed(robot: WorldRobot) -> LineSpeed:
    """The world's speed loop for speedj/speedl lines, made at its first use."""
    loop = robot.speed_loop
    if not isinstance(loop, LineSpeed):
        loop = robot.speed_loop = LineSpeed(robot)
    return loop


def run(robot: WorldRobot, call: urscript.Call) -> None:
    """Carry out one call on `robot`'s world; Refused (or urscript.ScriptError) otherwise."""
    a = urscript.bind(call)
    robot.end_script(f"a line of URScript ({call.name}) replaced it")
    speed = line_speed(robot)
    speed.end()
    try:
        _carry_out(robot, call.name, a, speed)
    except (BadCommand, ProtectiveStopped) as exc:
        raise Refused(f"{call.name}(): {exc}") from None


def _carry_out(robot: WorldRobot, name: str, a: dict[str, Any], speed: LineSpeed) -> None:
    m, w = robot.motion, robot.world
    if name == "movej":
        q = np.array(a["q"])
        if a["is_pose"]:
            q = _ik(robot, q, name)
        v = a["v"]
        if a["t"] > 0:
            v = speed_for(float(np.abs(q - m.targets(w)).max()), a["a"], a["t"])
        m.move_joints(w, q, v, a["a"])
    elif name == "movel":
        pose = np.array(a["pose"])
        if not a["is_pose"]:
            pose = m.fk(pose, m.tcp(w))
        v = a["v"]
        if a["t"] > 0:
            now = m.fk(m.targets(w), m.tcp(w))
            v = speed_for(float(np.linalg.norm(pose[:3] - now[:3])), a["a"], a["t"])
        m.move_linear(w, pose, v, a["a"])
    elif name == "servoj":
        m.servo(w, np.array(a["q"]))
    elif name in ("speedj", "speedl"):
        speed.start("joint" if name == "speedj" else "tool", a["qd" if name == "speedj" else "xd"],
                    a["a"], a["t"])  # fmt: skip
    elif name in ("stopj", "stopl"):
        m.stop(w, a["a"])
    elif name == "set_tcp":
        m.set_tcp(w, a["pose"])
    elif name == "set_payload":
        m.set_payload(w, a["m"], a["cog"])
    else:  # signal_async_progress: only inside ur_rtde's paths
        raise Refused(f"{name}() is not carried out on its own")


def _ik(robot: WorldRobot, pose: np.ndarray, name: str) -> np.ndarray:
    m, w = robot.motion, robot.world
    q = m.ik(pose, m.targets(w), m.tcp(w))
    if q is None:
        raise Refused(f"{name}(): no joint configuration reaches {pose.tolist()}")
    return q
