"""The scene's entities: every named free body, in every world, and how to read them.

An entity is a body whose joint is a MuJoCo free joint: its pose is 7 numbers of the world's
qpos (position x y z [m], orientation w x y z) and its twist 6 of qvel (linear velocity [m/s] in
the world frame, angular velocity [rad/s] in the body's own frame, as MuJoCo stores a free
joint's). The table is what the loop, the streams and the `set_entity` command
(service.core.commands.entities) share; reading happens on the sim thread.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from service.core.errors import BadCommand
from service.core.sim.batch import Batch
from service.core.sim.types import EntityFrame

__all__ = ["EntityTable", "entity_table", "read", "read_frame"]

BOUNDS_NUMERIC = "armfleet_bounds"


@dataclass(frozen=True)
class EntityTable:
    """The scene's entities: names, each one's qpos and qvel address, the scene's bounds.

    names: entity names in body order; body: their body ids; qpos: first qpos address of each
    free joint (7 values follow); qvel: first dof address (6 follow); lower / upper: (3,) [m]
    """

    names: tuple[str, ...]
    body: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    def index(self, name: object, field: str = "name") -> int:
        if not isinstance(name, str) or name not in self.names:
            raise BadCommand(field, f"unknown entity {name!r}; entities are {list(self.names)}")
        return self.names.index(name)

    def bounds_text(self) -> str:
        return ", ".join(
            f"{a} {lo:g}..{hi:g} m" for a, lo, hi in zip("xyz", self.lower, self.upper, strict=True)
        )


def free_bodies(mjm: mujoco.MjModel) -> list[tuple[int, int]]:
    """(body id, free joint id) of every free body, in body order."""
    return [
        (int(mjm.jnt_bodyid[j]), j)
        for j in range(mjm.njnt)
        if mjm.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
    ]


def scene_bounds(mjm: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Where an entity may be put: `armfleet_bounds` if the model has it, else centre ± extent."""
    nid = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_NUMERIC, BOUNDS_NUMERIC)
    if nid >= 0 and mjm.numeric_size[nid] == 6:
        adr = mjm.numeric_adr[nid]
        values = np.array(mjm.numeric_data[adr : adr + 6], dtype=np.float64)
        return values[:3], values[3:]
    centre, extent = np.array(mjm.stat.center, dtype=np.float64), float(mjm.stat.extent)
    return centre - extent, centre + extent


# Per model object, for as long as it lives (a model freed and another made at its address must
# not find the first one's table).
_TABLES: weakref.WeakKeyDictionary[mujoco.MjModel, EntityTable] = weakref.WeakKeyDictionary()


def entity_table(mjm: mujoco.MjModel) -> EntityTable:
    """The entity table of a compiled model (built once per model object)."""
    table = _TABLES.get(mjm)
    if table is None:
        found = free_bodies(mjm)
        names = tuple(mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_BODY, b) or "" for b, _ in found)
        lower, upper = scene_bounds(mjm)
        table = EntityTable(
            names=names,
            body=np.array([b for b, _ in found], dtype=np.int64),
            qpos=np.array([mjm.jnt_qposadr[j] for _, j in found], dtype=np.int64),
            qvel=np.array([mjm.jnt_dofadr[j] for _, j in found], dtype=np.int64),
            lower=lower,
            upper=upper,
        )
        _TABLES[mjm] = table
    return table


# -- reading ------------------------------------------------------------------------------


def read_frame(batch: Batch, ids: Sequence[int] | np.ndarray | None = None) -> EntityFrame:
    """Entities of worlds `ids` (all when None), in that order, at the batch's last tick (call
    on the sim thread: `SimLoop.call`). One host copy of qpos and qvel.

    Values are the engine's own state (float32 on MuJoCo Warp, float64 on native MuJoCo), so
    a written value reads back as the engine holds it.
    """
    table = entity_table(batch.robot.mjm)
    qpos, qvel = batch.qpos(), batch.qvel()
    rows = np.arange(qpos.shape[0]) if ids is None else np.asarray(ids, dtype=np.int64)
    pose = qpos[rows][:, table.qpos[:, None] + np.arange(7)]  # (k, ne, 7)
    twist = qvel[rows][:, table.qvel[:, None] + np.arange(6)]  # (k, ne, 6)
    return EntityFrame(
        names=table.names,
        worlds=rows,
        position=np.ascontiguousarray(pose[..., :3]),
        orientation=np.ascontiguousarray(pose[..., 3:]),
        linear=np.ascontiguousarray(twist[..., :3]),
        angular=np.ascontiguousarray(twist[..., 3:]),
    )


def read(batch: Batch, worlds: Sequence[int]) -> dict[str, Any]:
    """Entities of `worlds` at the batch's last tick, as GET /v1/worlds/{w}/entities answers
    (sim thread only, as `read_frame`)."""
    frame = read_frame(batch, worlds)
    fields = ("position", "orientation", "linear", "angular")
    rows = [
        {
            "world": int(w),
            "entities": [
                {"name": name, **{f: getattr(frame, f)[i, e].tolist() for f in fields}}
                for e, name in enumerate(frame.names)
            ],
        }
        for i, w in enumerate(frame.worlds)
    ]
    return {"tick": batch.tick, "worlds": rows}
