"""The host side of a Warp engine's snapshot: the gathered state's columns, and the Snapshot
made of the contiguous arrays the gather kernels write (views, no copy), which process and Ray
shards ship whole and join.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from service.core.sim.types import Poses, Snapshot

NJOINT = 7
# Columns of the gathered state array, one row per world.
_POS, _VEL, _EFF = (slice(i * NJOINT, (i + 1) * NJOINT) for i in range(3))
_FPOS = slice(3 * NJOINT, 3 * NJOINT + 3)
_FQUAT = slice(3 * NJOINT + 3, 3 * NJOINT + 7)
NCOL = 3 * NJOINT + 7


class SnapshotArrays(NamedTuple):
    """A Snapshot before it is cut into fields: contiguous host arrays, as the gather kernels
    write them, so that shipping one between processes copies no field on its own.

    state: position, velocity, effort, flange_pos, flange_quat side by side   (nworld, 28) f32
    bodies: body_pos then body_quat of every body                          (nworld, nbody, 7) f32
    sim_time, faults: as in Snapshot                                                 (nworld,)
    """

    tick: int
    sim_time: np.ndarray
    state: np.ndarray
    bodies: np.ndarray
    faults: np.ndarray


def snapshot_from(a: SnapshotArrays, target: np.ndarray) -> Snapshot:
    """The Snapshot whose fields are views of `a`'s arrays (no copy); `target` is the caller's."""
    state, bodies = a.state, a.bodies
    return Snapshot(
        tick=a.tick,
        sim_time=a.sim_time,
        position=state[:, _POS],
        velocity=state[:, _VEL],
        effort=state[:, _EFF],
        target=target,
        faults=a.faults,
        flange=Poses(state[:, _FPOS], state[:, _FQUAT]),
        bodies=Poses(bodies[:, :, :3], bodies[:, :, 3:]),
    )
