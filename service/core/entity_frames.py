"""Entities in state frames, for the clients that ask (`entities=true`): read on the sim thread.

A state frame's joints come from the engine's rows of one tick; a client that asks for entities
gets each entity's pose and twist of that same tick, so they are read where the tick is, between
two ticks on the sim thread: from qpos/qvel (`read`), for the worlds of a packed frame or, while
some client asks, for every world of a published snapshot (`attach`). Nobody asking costs
nothing: no read, no field, the frames' bytes unchanged. The frames' shapes are wire.py's
(`entity_columns`, `entity_list`).
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from service.core.batch import Batch
from service.core.commands.entities import entity_table
from service.core.types import EntityFrame, Snapshot

__all__ = ["attach", "read"]

log = logging.getLogger("armfleet.entities")


def read(batch: Batch, ids: np.ndarray | None = None) -> EntityFrame:
    """Entities of worlds `ids` (all when None) at the batch's last tick (sim thread only).

    One host copy of qpos and qvel: the cost a client pays for asking, per frame.
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


def attach(snap: Snapshot, batch: Batch) -> Snapshot:
    """`snap` with every world's entities, read now (sim thread, at `snap`'s tick); `snap` as
    it is when the engine cannot give them now (a Ray shard being rebuilt): the frames that
    need them wait for the next snapshot."""
    try:
        return dataclasses.replace(snap, entities=read(batch))
    except Exception:
        log.exception("the entities of tick %d could not be read", snap.tick)
        return snap
