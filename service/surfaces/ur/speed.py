"""speedj, speedl and the pendant's jog as position targets, integrated on a timer.

A UR's speed commands hold a joint or tool velocity until another command comes; armfleet's
servos take position targets, so the runner's timer (script_runner.py, every 8 ms) moves the
arm's targets on by the commanded velocity, reached and left at the commanded acceleration.
speedl's tool twist (x y z [m/s], rx ry rz [rad/s], base frame) becomes joint velocities
through the Jacobian at the current target (with the TCP offset); a jog's speed is given in
the base frame, the tool frame as it was when the jog started, or a custom frame. No joint
turns faster than its limit (the command is scaled down, as the robot's speed scaling does),
and a target that would leave a joint's range ends the motion with BadCommand.
"""

from __future__ import annotations

import numpy as np

from service.core.errors import BadCommand
from service.core.kinematics.pose import pose_to_matrix
from service.surfaces.ur.motion import Motion


class SpeedLoop:
    """One world's speed motion: off, joint velocities, or a tool twist (base frame)."""

    def __init__(self, motion: Motion, world: int) -> None:
        self.motion, self.world = motion, world
        self.kind: str | None = None
        self.want = np.zeros(6)
        self.accel = 1.0
        self.v = np.zeros(6)  # the joints' commanded velocity now
        self.q: np.ndarray | None = None  # the integrated target

    @property
    def active(self) -> bool:
        return self.kind is not None

    def begin(self, kind: str, speed: list[float], accel: float) -> None:
        """speedj (kind "joint": rad/s) or speedl ("tool": twist in the base frame)."""
        if self.kind is None:
            self.q = self.motion.targets(self.world)
            self.v = np.zeros(6)
        self.kind, self.want, self.accel = kind, np.asarray(speed, np.float64), accel

    def jog(self, speed: list[float], feature: int, accel: float, frame: list[float]) -> None:
        """jogStart: a tool speed in the base (0), tool (1) or custom (2) frame."""
        v = np.asarray(speed, np.float64)
        if feature:
            if feature == 1:
                m = self.motion
                pose = m.fk(m.targets(self.world), m.tcp(self.world))
            else:
                pose = np.asarray(frame)
            rot = pose_to_matrix(pose)[:3, :3]
            v = np.concatenate([rot @ v[:3], rot @ v[3:]])
        self.begin("tool", v.tolist(), accel)

    def end(self) -> None:
        self.kind, self.q = None, None
        self.v = np.zeros(6)

    def step(self, dt: float) -> None:
        if self.kind is None or self.q is None:
            return
        m = self.motion
        want = self.want
        if self.kind == "tool":
            jac = m.tools.kin.jacobian(self.q[None], m.tcp(self.world)[None])[0]
            want = np.linalg.lstsq(jac, self.want, rcond=None)[0]
        peak = float(np.max(np.abs(want) / m.speed_limits))
        if peak > 1.0:
            want = want / peak
        change = want - self.v
        most = self.accel * dt
        size = float(np.abs(change).max())
        self.v = self.v + (change * (most / size) if size > most else change)
        q = self.q + self.v * dt
        outside = (q < m.lower) | (q > m.upper)
        if outside.any():
            j = int(np.argmax(outside))
            self.end()
            raise BadCommand("speed", f"{m.names[j]} reached the end of its range")
        self.q = q
        m.servo(self.world, q)
