"""What the loop lends a trajectory runner: its pending command tables, under its lock.

`SimLoop.staging()` yields a `Staging` with the command lock held; `TrajectoryHook` is what the
loop calls on the runner at each stage of a tick (service.core.trajectory.TrajectoryManager is the
one implementation). Kept apart from the loop so that neither module imports the other's
internals, and the loop never imports the trajectory package.
"""

from __future__ import annotations

import enum
from typing import NamedTuple, Protocol

import numpy as np

from service.core.types import Snapshot


class Staging(NamedTuple):
    """The loop's pending tables, to edit in place while the command lock is held.

    pending: targets as of every accepted command [rad]                        (nworld, 7)
    velocity: velocity feed-forward staged with them [rad/s] (0 = plain servo) (nworld, 7)
    dirty: rows to hand to the engine at the next tick boundary                 (nworld,) bool
    tick: the first tick stepped with what is staged now
    """

    pending: np.ndarray
    velocity: np.ndarray
    dirty: np.ndarray
    tick: int


class Override(enum.StrEnum):
    """Why the loop stops a world's trajectory on its own."""

    MANUAL = "manual_override"
    RESET = "reset"


class TrajectoryHook(Protocol):
    """Called by the loop with its command lock held (except `dispatch`)."""

    def overridden(
        self, worlds: np.ndarray, reason: Override, joints: np.ndarray | None = None
    ) -> None:
        """A target command (naming `joints`, indices) or a reset (None: all) was staged."""

    def sample(self, tick: int, st: Staging) -> None:
        """Stage the desired targets of tick `tick` (just before it is stepped)."""

    def after_step(self, tick: int, faulted: np.ndarray, st: Staging) -> bool:
        """Tick `tick` was stepped (`faulted` worlds were reset); True: snapshot it."""

    def observe(self, snap: Snapshot, st: Staging) -> None:
        """A snapshot was taken (of the last stepped tick, or after a restore)."""

    def restored(self) -> None:
        """The batch was restored from a saved state."""

    def dispatch(self) -> None:
        """After the tick, no lock held: hand finished trajectories to their listeners."""
