"""The tool's pose and speed in the robot's base frame from MuJoCo's own kinematics, world by
world: RTDE's fallback for a served arm that is not UR's DH chain (a cell that changed it; the
TCP is then the flange). UR's arm is read in one batch for every world instead
(`rtde_frame`, `URKinematics.tcp_state`); tests/test_kinematics.py holds the two equal.

It reads MuJoCo's own body poses of the served model: a scratch MjData of the scene, the
arm's six joints set from the world's state, `mj_kinematics` for the flange site's pose and
`mj_jacSite` for its twist (J(q)·q̇), both expressed in the frame of the body `base` (the
controller's base frame, UR's DH frame 0; a cell without one uses the root body of the
flange's chain). UR poses are x, y, z [m] and a rotation vector rx, ry, rz [rad] (angle ≤ π).
"""

from __future__ import annotations

import mujoco
import numpy as np

from service.core.sim.robot import LoadedRobot

ARM = 6  # the six arm joints come first in command order (types.NJOINT: then the finger)


def rotvec(rot: np.ndarray) -> np.ndarray:
    """The rotation vector (axis × angle, angle in [0, π]) of a 3×3 rotation matrix."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rot, dtype=np.float64).reshape(9))
    if quat[0] < 0:
        quat = -quat
    s = float(np.linalg.norm(quat[1:]))
    if s < 1e-12:
        return np.zeros(3)
    angle = 2.0 * np.arctan2(s, quat[0])
    return quat[1:] / s * angle


def rotation(rv: np.ndarray) -> np.ndarray:
    """The 3×3 rotation matrix of a rotation vector."""
    angle = float(np.linalg.norm(rv))
    if angle < 1e-15:
        return np.eye(3)
    quat = np.empty(4)
    mujoco.mju_axisAngle2Quat(quat, np.asarray(rv, dtype=np.float64) / angle, angle)
    out = np.empty(9)
    mujoco.mju_quat2Mat(out, quat)
    return out.reshape(3, 3)


class ToolKinematics:
    """Flange (and TCP) pose and twist in the base frame from the arm's joints (one thread)."""

    def __init__(self, robot: LoadedRobot) -> None:
        m = robot.mjm
        self._m, self._d = m, mujoco.MjData(m)
        self._site = robot.flange_site
        self._qadr = np.asarray(robot.qpos_adr[:ARM])
        self._vadr = np.asarray(robot.dof_adr[:ARM])
        self._jacp, self._jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base")
        if base < 0:  # a cell of its own naming: the root of the flange's chain
            base = int(m.site_bodyid[self._site])
            while int(m.body_parentid[base]) != 0:
                base = int(m.body_parentid[base])
        d = self._d
        d.qpos[:] = m.qpos0
        mujoco.mj_kinematics(m, d)
        self._base_pos = d.xpos[base].copy()  # fixed: nothing moves the base
        self._base_rot_t = d.xmat[base].reshape(3, 3).T.copy()

    def flange(self, q: np.ndarray, qd: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """(position (3,), rotation (3, 3)[, linear (3,), angular (3,) velocity]) of the flange
        in the base frame at arm joints `q` (6,) [rad], moving at `qd` (6,) [rad/s] if given."""
        m, d = self._m, self._d
        d.qpos[:] = m.qpos0
        d.qpos[self._qadr] = q[:ARM]
        mujoco.mj_kinematics(m, d)
        rt = self._base_rot_t
        pos = rt @ (d.site_xpos[self._site] - self._base_pos)
        rot = rt @ d.site_xmat[self._site].reshape(3, 3)
        if qd is None:
            return pos, rot
        mujoco.mj_comPos(m, d)
        mujoco.mj_jacSite(m, d, self._jacp, self._jacr, self._site)
        v = rt @ (self._jacp[:, self._vadr] @ qd[:ARM])
        w = rt @ (self._jacr[:, self._vadr] @ qd[:ARM])
        return pos, rot, v, w

    def tcp(
        self, q: np.ndarray, qd: np.ndarray, offset: tuple[float, ...]
    ) -> tuple[np.ndarray, np.ndarray]:
        """(pose x y z rx ry rz, speed vx vy vz wx wy wz) of the TCP, `offset` (x y z rx ry rz,
        set_tcp's pose in the flange frame) from the flange, in the base frame."""
        pos, rot, v, w = self.flange(q, qd)
        if any(offset):
            lever = rot @ np.asarray(offset[:3])
            pos = pos + lever
            v = v + np.cross(w, lever)
            rot = rot @ rotation(np.asarray(offset[3:]))
        return np.concatenate([pos, rotvec(rot)]), np.concatenate([v, w])
