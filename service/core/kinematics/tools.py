"""Each world's TCP offset (UR's `set_tcp`) and the served arm's kinematics, one table per loop.

Why here and not in the loop: the offset is no state of the physics (MuJoCo never sees it); it
only turns joint angles into the TCP pose a program speaks of, and a TCP pose into joint
targets. It describes the tool, like the payload: kept through resets, per world, zero (the
flange) until set. Every Cartesian command and read asks `tools_of(loop)` for the same table.
"""

from __future__ import annotations

import threading
import weakref
from typing import TYPE_CHECKING

import numpy as np

from service.core.errors import Unavailable
from service.core.kinematics.servo import ServoLag
from service.core.kinematics.ur import NotDH, URKinematics, of_model

if TYPE_CHECKING:
    from service.core.sim.loop import SimLoop

__all__ = ["ToolTable", "tools_of"]


class ToolTable:
    """TCP offsets p[x, y, z, rx, ry, rz] of `nworld` worlds in the flange frame, and `kin`
    (thread-safe: surfaces read it while commands write it)."""

    def __init__(self, kin: URKinematics, nworld: int, lag: ServoLag | None = None) -> None:
        self.kin = kin
        self.lag = lag  # the arm's servo lag, for moveL's acceleration feed-forward
        self._tcp = np.zeros((nworld, 6))
        self._lock = threading.Lock()
        self.version = 0  # bumped by every `set`: a reader keeps a copy until it moves

    def all(self) -> tuple[int, np.ndarray]:
        """(version, every world's offsets (nworld, 6)) read together (RTDE: once per tick)."""
        with self._lock:
            return self.version, self._tcp.copy()

    def get(self, worlds: np.ndarray | list[int] | int) -> np.ndarray:
        """The offsets of `worlds` (k, 6), or (6,) for one world id."""
        with self._lock:
            return self._tcp[worlds].copy()

    def set(self, worlds: np.ndarray | list[int], offsets: np.ndarray) -> None:
        """Give `worlds` (k,) the offsets (k, 6) (validated by the caller: `commands.tcp`)."""
        with self._lock:
            self._tcp[np.asarray(worlds, dtype=np.int64)] = offsets
            self.version += 1


_TABLES: weakref.WeakKeyDictionary[SimLoop, ToolTable] = weakref.WeakKeyDictionary()
_MADE = threading.Lock()


def tools_of(loop: SimLoop) -> ToolTable:
    """The loop's table (made on first use); Unavailable (503) when the served arm is not UR's
    DH chain (a cell that changed the arm), naming what differs."""
    with _MADE:
        table = _TABLES.get(loop)
        if table is None:
            mjm, arm = loop.batch.robot.mjm, loop.spec.names[:6]
            try:
                kin = of_model(mjm, arm)
            except NotDH as exc:
                raise Unavailable(f"no Cartesian commands on this arm: {exc}") from None
            table = _TABLES[loop] = ToolTable(kin, loop.batch.nworld, ServoLag(mjm, arm))
        return table
