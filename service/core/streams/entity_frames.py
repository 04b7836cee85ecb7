"""Entities in state frames, for the clients that ask (`entities=true`): read on the sim thread.

A state frame's joints come from the engine's rows of one tick; a client that asks for entities
gets each entity's pose and twist of that same tick, so they are read where the tick is, between
two ticks on the sim thread: from qpos/qvel (`read`, the entity commands' own reader), for
the worlds of a packed frame or, while some client asks, for every world of a published
snapshot (`attach`). Nobody asking costs
nothing: no read, no field, the frames' bytes unchanged. The frames' shapes are wire.py's
(`entity_columns`, `entity_list`).
"""

from __future__ import annotations

import dataclasses
import logging

from service.core.sim.batch import Batch
from service.core.sim.entities import read_frame as read
from service.core.sim.types import Snapshot

__all__ = ["attach", "read", "snapshot_with_entities"]

log = logging.getLogger("armfleet.entities")


def attach(snap: Snapshot, batch: Batch) -> Snapshot:
    """`snap` with every world's entities, read now (sim thread, at `snap`'s tick); `snap` as
    it is when the engine cannot give them now (a Ray shard being rebuilt): the frames that
    need them wait for the next snapshot."""
    try:
        return dataclasses.replace(snap, entities=read(batch))
    except Exception:
        log.exception("the entities of tick %d could not be read", snap.tick)
        return snap


def snapshot_with_entities(batch: Batch) -> Snapshot:
    """A snapshot of the batch's tick with every world's entities (for `SimLoop.call`: the
    first frame of a socket that asked for entities before anyone else did)."""
    return attach(batch.snapshot(), batch)
