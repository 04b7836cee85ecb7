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

import mujoco
import numpy as np
from mujoco import batch as mjbatch

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
