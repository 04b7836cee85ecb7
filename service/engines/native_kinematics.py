"""Body and site poses at the reported state, for the native engine's snapshots and frames.

After ``mujoco.batch.Batch.step`` the derived fields describe the state before the last
substep, so the pose a snapshot reports has to be computed again at the current qpos. Running
the batch's own ``forward(stage=mjSTAGE_POS)`` does that but also collision detection and
constraint assembly: a quarter of a 2-substep tick at 1024 worlds (measured for issue 20), paid
for every snapshot. Here a second batch of the same model, with contacts and constraints
disabled, runs the position stage on a copy of the qpos rows: the same kinematics (poses are
bit-identical; they do not depend on those flags) at about a third of the cost, and only for the
worlds asked for. Frames need only the flange: service.engines.chain_pose computes it in numpy.
"""

from __future__ import annotations

import copy
import threading

import mujoco
import numpy as np
from mujoco import batch as mjbatch

from service.engines.chain_pose import ChainPose

# Everything the position stage may skip without changing a pose.
_SKIP = (
    mujoco.mjtDisableBit.mjDSBL_CONTACT
    | mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    | mujoco.mjtDisableBit.mjDSBL_ACTUATION
)


class Kinematics:
    """Poses of `nworld` worlds of `mjm` at qpos rows handed in (`update`)."""

    def __init__(self, mjm: mujoco.MjModel, nworld: int, nthread: int) -> None:
        model = copy.copy(mjm)
        model.opt.disableflags |= int(_SKIP)
        self._b = mjbatch.Batch(model, nworld, nthread=nthread)
        self._qpos = self._b.bind("qpos")
        self.xpos = self._b.bind("xpos")  # (nworld, nbody, 3), live views
        self.xquat = self._b.bind("xquat")  # (nworld, nbody, 4), w x y z
        self.site_xpos = self._b.bind("site_xpos")  # (nworld, nsite, 3)

    def update(self, qpos: np.ndarray, ids: np.ndarray | None = None) -> None:
        """Poses at `qpos` (nworld, nq) for worlds `ids` (all when None)."""
        rows = qpos if ids is None else qpos[ids]
        if ids is None:
            self._qpos[:] = rows
        else:
            self._qpos[ids] = rows
        self._b.forward(ids, stage=mujoco.mjtStage.mjSTAGE_POS)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (w, x, y, z), row-wise: (n, 4) x (4,) -> (n, 4)."""
    aw, ax, ay, az = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    bw, bx, by, bz = b
    return np.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        axis=1,
    )


class PoseReader:
    """The poses a native snapshot or frame reports, at qpos rows handed in: the flange (the
    arm's chain in numpy, `ChainPose`, on the calling thread; MuJoCo's kinematics for a model
    whose flange is not on a chain of hinges and slides) and every body (`Kinematics`, from
    any thread: the kinematics batch is used under a lock)."""

    def __init__(self, mjm: mujoco.MjModel, nworld: int, nthread: int, flange: int) -> None:
        self._nworld = nworld
        self._flange = flange
        self._flange_body = int(mjm.site_bodyid[flange])
        self._flange_local_quat = np.array(mjm.site_quat[flange], dtype=np.float64)
        self._kin = Kinematics(mjm, nworld, nthread)  # body poses, read on demand
        self._lock = threading.Lock()
        try:  # the flange alone, for frames and snapshots: numpy on one core
            self._chain: ChainPose | None = ChainPose(mjm, flange)
        except ValueError:  # not a chain of hinges and slides: MuJoCo's kinematics
            self._chain = None

    def flange(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flange position and quaternion (w x y z) at qpos rows (k, nq), float64."""
        if self._chain is not None:
            return self._chain.pose(qpos)
        _, xquat, site_xpos = self._bodies(qpos)
        body_quat = xquat[:, self._flange_body]
        return site_xpos[:, self._flange], _quat_mul(body_quat, self._flange_local_quat)

    def flange_f32(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The flange pose at qpos rows as a snapshot reports it (float32, C order)."""
        pos, quat = self.flange(qpos)
        return pos.astype(np.float32, order="C"), quat.astype(np.float32, order="C")

    def bodies_f32(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every body's pose at qpos (nworld, nq), float32: what a snapshot's poses read."""
        xpos, xquat, _ = self._bodies(qpos)
        return xpos.astype(np.float32), xquat.astype(np.float32)

    def _bodies(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """MuJoCo's body positions, body quaternions and site positions at qpos rows (k, nq),
        copied."""
        ids = np.arange(len(qpos))  # the batch's first k rows take the k rows given
        with self._lock:
            self._kin.update(qpos, None if len(qpos) == self._nworld else ids)
            return self._kin.xpos[ids], self._kin.xquat[ids], self._kin.site_xpos[ids]
