"""Body and site poses at the reported state, for the native engine's snapshots and frames.

After ``mujoco.batch.Batch.step`` the derived fields describe the state before the last
substep, so the pose a snapshot reports has to be computed again at the current qpos. Running
the batch's own ``forward(stage=mjSTAGE_POS)`` does that but also collision detection and
constraint assembly: a quarter of a 2-substep tick at 1024 worlds (measured for issue 20), paid
for every snapshot. Here a second batch of the same model, with contacts and constraints
disabled, runs the position stage on a copy of the qpos rows: the same kinematics (poses are
bit-identical; they do not depend on those flags) at about a third of the cost, and only for the
worlds asked for. Frames need only the flange: a third batch of the model cut down to the arm's
chain (`chain_to`) computes it for about half as much again.
"""

from __future__ import annotations

import copy
from typing import Any

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
    """Poses of `nworld` worlds of `mjm` at qpos rows handed in (`update`).

    `qpos_adr`: which of the full model's qpos columns this model's are (all when None).
    """

    def __init__(
        self,
        mjm: mujoco.MjModel,
        nworld: int,
        nthread: int,
        qpos_adr: np.ndarray | None = None,
    ) -> None:
        model = copy.copy(mjm)
        model.opt.disableflags |= int(_SKIP)
        self._cols = qpos_adr
        self._b = mjbatch.Batch(model, nworld, nthread=nthread)
        self._qpos = self._b.bind("qpos")
        self.xpos = self._b.bind("xpos")  # (nworld, nbody, 3), live views
        self.xquat = self._b.bind("xquat")  # (nworld, nbody, 4), w x y z
        self.site_xpos = self._b.bind("site_xpos")  # (nworld, nsite, 3)

    def update(self, qpos: np.ndarray, ids: np.ndarray | None = None) -> None:
        """Poses at `qpos` (nworld, nq) for worlds `ids` (all when None)."""
        rows = qpos if ids is None else qpos[ids]
        if self._cols is not None:
            rows = rows[:, self._cols]
        if ids is None:
            self._qpos[:] = rows
        else:
            self._qpos[ids] = rows
        self._b.forward(ids, stage=mujoco.mjtStage.mjSTAGE_POS)


def chain_to(spec: mujoco.MjSpec, mjm: mujoco.MjModel, body: int) -> tuple[mujoco.MjModel, Any]:
    """The model cut down to `body` and its ancestors (nothing else: no gripper, no cube, no
    actuators or constraints), and the full model's qpos columns of its joints.

    A body's pose depends only on its ancestors, and MuJoCo computes it the same way in either
    model: its poses are bit-identical to the full model's (tests/test_frames.py), for a
    fraction of the work a world.
    """
    keep: set[str] = set()
    while body > 0:
        keep.add(mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_BODY, body))
        body = int(mjm.body_parentid[body])
    for group in (spec.equalities, spec.actuators, spec.sensors, spec.excludes, spec.pairs):
        for item in list(group):
            spec.delete(item)
    for item in list(spec.tendons) + list(spec.keys):
        spec.delete(item)

    def prune(parent: Any) -> None:
        for child in list(parent.bodies):
            if child.name in keep:
                prune(child)
            else:
                spec.delete(child)

    prune(spec.worldbody)
    chain = spec.compile()
    names = [mujoco.mj_id2name(chain, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(chain.njnt)]
    adr = [mjm.jnt_qposadr[mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in names]
    chain.opt.timestep = mjm.opt.timestep
    return chain, np.array(adr)
