"""The loop's command table (`CommandTable`), and what the loop lends a trajectory runner: the
table's arrays, under the loop's lock.

`SimLoop.staging()` yields a `Staging` with the command lock held; `TrajectoryHook` is what the
loop calls on the runner at each stage of a tick
(service.core.commands.trajectory.TrajectoryManager is the one implementation). Kept apart from
the loop so that neither module imports the other's internals, and the loop never imports the
trajectory package.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from typing import NamedTuple, Protocol

import numpy as np

from service.core.sim.arithmetic import TargetUpdate
from service.core.sim.batch import ModelWrite, StateWrite, TickWrites
from service.core.sim.loop_types import CommandResult
from service.core.sim.types import Snapshot

_NOTHING = TickWrites()  # what `take` hands when nothing is staged (never written: it is empty)
_NOTHING.targets.flags.writeable = False


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


class CommandTable:
    """The loop's one command table: what accepted commands staged and the engine has not yet
    been handed. The loop holds its lock around every method (commands arrive on any thread;
    `take` runs on the sim thread); the loop owns time, this owns what was staged.

    pending: targets as of all accepted commands [rad]              (nworld, 7) float64
    velocity: feed-forward staged with them [rad/s]                  (nworld, 7) float64
    dirty / reset: worlds whose targets / reset go to the engine next      (nworld,) bool
    state: qpos/qvel slices and per-world model values, in the order staged
    effective: per world, the tick its latest accepted command takes effect at   (nworld,)
    changes: a count that moves whenever `pending` may have changed (a command staged, a
        trajectory's samples taken, a fault, a restore, the tables lent): a reader that saw
        the same count has nothing new to compare (the clearance watch, after every tick).
        Whoever writes `dirty` through a lent `Staging` moves it too (`CommandDesk.wrote`):
        `take` looks at nothing while the count is where its last emptying left it.
    """

    def __init__(self, targets: np.ndarray, home: np.ndarray) -> None:
        self.home = home
        self.pending = np.array(targets, dtype=np.float64)
        self.velocity = np.zeros_like(self.pending)
        self.dirty = np.zeros(len(targets), dtype=bool)
        self.reset = np.zeros(len(targets), dtype=bool)
        self.state: list[StateWrite | ModelWrite] = []
        self.effective = np.zeros(len(targets), dtype=np.int64)
        self.changes = 0
        self._empty_at = 0  # `changes` when the table was last left empty (nothing staged)

    def view(self, tick: int) -> Staging:
        """The tables a trajectory runner edits in place, for commands taking effect at `tick`."""
        return Staging(self.pending, self.velocity, self.dirty, tick)

    def stage_rows(
        self,
        worlds: Sequence[int],
        update: Callable[[int, np.ndarray], TargetUpdate],
        tick: int,
    ) -> list[CommandResult]:
        """New target rows, each `update(world, its latest row)` so that commands compose."""
        out = []
        self.changes += 1
        for world in worlds:
            row = update(world, self.pending[world])
            self.pending[world] = row.target
            self.velocity[world] = 0.0  # a trajectory that goes on writes its own next tick
            self.dirty[world] = True
            self.effective[world] = tick
            out.append(CommandResult(world, row.target.copy(), row.clamped, tick))
        return out

    def stage_reset(self, worlds: np.ndarray, tick: int) -> None:
        """Worlds back at home; a reset staged later wins over their earlier target and state
        writes of the same tick boundary (model values stay: they are not state)."""
        self.reset[worlds] = True
        self.dirty[worlds] = False
        self.changes += 1
        if self.state:
            gone = set(worlds.tolist())
            self.state = [w for w in self.state if isinstance(w, ModelWrite) or w.world not in gone]
        self.pending[worlds] = self.home
        self.velocity[worlds] = 0.0
        self.effective[worlds] = tick

    def stage_state(self, writes: Sequence[StateWrite | ModelWrite], tick: int) -> None:
        self.state.extend(writes)
        for w in writes:
            self.effective[w.world] = tick

    def has_writes(self) -> bool:
        """Is anything staged for the engine?"""
        return bool(self.state) or bool(self.dirty.any()) or bool(self.reset.any())

    def take(self) -> TickWrites:
        """Everything staged, as the engine's `TickWrites`; the table starts empty again.

        Most ticks of a large batch stage nothing: then no index arrays are built (a tick's
        serial Python work leaves the engine's other cores idle), and while the change count
        stands where the last emptying left it not even the flags are scanned: at 16,384
        worlds that scan was most of the ~25 us a tick cost the sim thread on an H200's host
        with the device idle (bench/results/issue39/gpu7)."""
        if self.changes == self._empty_at and not self.state:
            return _NOTHING
        if not self.state and not self.dirty.any() and not self.reset.any():
            self._empty_at = self.changes
            return _NOTHING
        self.changes += 1  # rows written through a `Staging` view (trajectories) set `dirty`
        dirty = np.flatnonzero(self.dirty)
        velocity = self.velocity[dirty].copy()
        writes = TickWrites(
            resets=np.flatnonzero(self.reset),
            worlds=dirty,
            targets=self.pending[dirty].copy(),
            velocities=velocity if velocity.any() else None,
            state=tuple(w for w in self.state if isinstance(w, StateWrite)),
            model=tuple(w for w in self.state if isinstance(w, ModelWrite)),
        )
        self.reset[:] = False
        self.dirty[:] = False
        self.state = []
        self._empty_at = self.changes
        return writes

    def faulted(self, worlds: np.ndarray) -> None:
        """The engine reset `worlds` for a fault: home, unless a command arrived since."""
        keep = worlds[~self.dirty[worlds]]
        self.pending[keep] = self.home
        self.velocity[keep] = 0.0
        self.changes += 1

    def restored(self, targets: np.ndarray, tick: int) -> None:
        """The batch continues from a saved state: what was staged belonged to the old one."""
        self.pending = np.array(targets, dtype=np.float64)
        self.changes += 1
        self.velocity[:] = 0.0
        self.dirty[:] = False
        self.reset[:] = False
        self.state = []
        self.effective[:] = tick
