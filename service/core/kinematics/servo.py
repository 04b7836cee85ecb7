"""How far the arm's position servos fall behind a target that accelerates: M(q) q̈ / kp.

Why: the trajectory runner feeds the target's velocity forward (ctrl = q + kv/kp × q̇), which
takes away the lag of a target moving at constant speed; one that accelerates still needs a
torque M(q) q̈ that only a position error kp × e gives, so each joint lags by M q̈ / kp, and as
inertias and gains differ from joint to joint the TCP leaves a straight line by millimetres
(4 mm at moveL's default 1.2 m/s², measured). A line's samples are shifted ahead by that lag,
from the served model's mass matrix and gains (the scene's; a world's own `kp` or payload
parameter is not seen here); with the samples on the loop's ticks (line.py says why) the TCP
keeps within 0.1 mm of the line at 1.2 m/s² (native MuJoCo, 60 to 500 Hz).
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

__all__ = ["ServoLag"]


class ServoLag:
    """The servo lag of the arm's joints `joints` (names) of `mjm` (position actuators)."""

    def __init__(self, mjm: mujoco.MjModel, joints: Sequence[str]) -> None:
        self.mjm = mjm
        ids = [mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joints]
        self.qpos_adr = mjm.jnt_qposadr[ids]
        self.dof_adr = mjm.jnt_dofadr[ids]
        kp = np.zeros(len(ids))
        for a in range(mjm.nu):  # the actuator driving each joint: its gain
            if mjm.actuator_trnid[a, 0] in ids:
                kp[ids.index(int(mjm.actuator_trnid[a, 0]))] = -mjm.actuator_biasprm[a, 1]
        self.kp = kp

    def offset(self, q: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """M(q) q̈ / kp (n, 6) [rad] for joint angles q and accelerations qdd (n, 6)."""
        m, data = self.mjm, mujoco.MjData(self.mjm)
        acc = np.zeros(m.nv)
        out = np.zeros_like(q)
        torque = np.zeros(m.nv)
        for k in range(len(q)):
            data.qpos[self.qpos_adr] = q[k]
            mujoco.mj_kinematics(m, data)
            mujoco.mj_comPos(m, data)
            mujoco.mj_crb(m, data)
            acc[self.dof_adr] = qdd[k]
            mujoco.mj_mulM(m, data, torque, acc)
            out[k] = torque[self.dof_adr]
        return np.where(self.kp > 0, out / np.where(self.kp > 0, self.kp, 1.0), 0.0)
