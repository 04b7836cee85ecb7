"""The loop's command side: what commands stage between ticks, under the loop's lock.

Why apart from the loop: commands arrive from any thread and only fold into the pending tables
(`CommandTable`), stop a trajectory they override, and note a randomisation; the loop thread
takes what is pending at each tick boundary. The desk owns that folding and nothing of time:
the tick a command takes effect at comes from the loop (`accept_tick`, read with the lock
held), so the rule "a command applies from the tick after the one in progress" is the loop's,
and so is when a paused loop applies a write at once (`staged`, told after every write).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from service.core.sim.arithmetic import TargetUpdate
from service.core.sim.batch import ModelWrite, StateWrite
from service.core.sim.loop_types import CommandResult
from service.core.sim.randomizations import RandomizationBook, Randomized
from service.core.sim.staging import CommandTable, Override, Staging, TrajectoryHook


class CommandDesk:
    """Stages targets, resets and state writes for the next tick boundary (any thread)."""

    def __init__(
        self,
        lock: threading.Lock,
        table: CommandTable,
        nworld: int,
        accept_tick: Callable[[], int],
        tick: Callable[[], int],
        staged: Callable[[], None] = lambda: None,
    ) -> None:
        self._lock = lock  # the loop's: the loop thread takes what is pending under it
        self.table = table
        self._nworld = nworld
        self._accept_tick = accept_tick  # the tick a command accepted now applies from
        self._tick = tick  # the last tick completed
        # Told (lock held) after every write staged: while paused the loop applies it at once.
        self._staged = staged
        self.traj: TrajectoryHook | None = None
        # Per world, the last randomisation (seed, spec) and its tick: snapshots name it.
        self.randomizations = RandomizationBook()

    def stage_rows(
        self,
        worlds: Sequence[int],
        update: Callable[[int, np.ndarray], TargetUpdate],
        joints: Iterable[int],
    ) -> list[CommandResult]:
        """Stage new target rows for `worlds` (valid ids: commands checked them), each made by
        `update(world, its latest row)` under the command lock so that commands compose; a
        trajectory stops only if it drives one of `joints` (indices)."""
        named = np.fromiter(joints, dtype=np.int64)
        with self._lock:
            out = self.table.stage_rows(worlds, update, self._accept_tick())
            if self.traj is not None and out:
                self.traj.overridden(np.asarray(worlds), Override.MANUAL, named)
            self._staged()
            return out

    def reset(
        self,
        worlds: list[int] | None = None,
        writes: Sequence[StateWrite | ModelWrite] = (),
        randomized: tuple[int, dict[str, Any]] | None = None,
    ) -> int:
        """Reset worlds (all when None) to home, state and targets; returns the effective tick.

        A randomisation's draws (`writes`) are staged for the same boundary, after the reset,
        and its (seed, spec) goes into `randomizations` with that tick, under the same lock.
        """
        idx = np.arange(self._nworld) if worlds is None else np.asarray(worlds, dtype=int)
        with self._lock:
            tick = self._accept_tick()
            self.table.stage_reset(idx, tick)
            if writes:
                self.table.stage_state(writes, tick)
            if randomized is not None:
                entry = Randomized(tick, *randomized)
                self.randomizations.record(idx.tolist(), entry, self._tick())
            if self.traj is not None:
                self.traj.overridden(idx, Override.RESET)
            self._staged()
            return tick

    def stage_state(self, writes: Sequence[StateWrite | ModelWrite]) -> int:
        """Stage qpos/qvel slices or per-world model values (validated by their command) for
        the next tick boundary, after that boundary's resets; the tick they take effect at."""
        with self._lock:
            tick = self._accept_tick()
            self.table.stage_state(writes, tick)
            self._staged()
            return tick

    def attach_trajectories(self, hook: TrajectoryHook) -> None:
        """Let `hook` run trajectories: the loop calls it at every stage of a tick."""
        self.traj = hook

    @contextlib.contextmanager
    def staging(self, worlds: np.ndarray | None = None) -> Iterator[Staging]:
        """Hold the command lock and lend the pending tables; `worlds` get the effective tick."""
        with self._lock:
            st = self.view()
            yield st
            self.table.changes += 1  # the tables were lent: they may have been written
            if worlds is not None:
                self.table.effective[worlds] = st.tick

    def view(self) -> Staging:
        """The pending tables for a trajectory runner (lock held)."""
        return self.table.view(self._accept_tick())

    def wrote(self) -> None:
        """Rows were staged through a `view` (lock held): the change count moves, so the next
        `take` looks for them and the clearance watch compares (`CommandTable.changes`)."""
        self.table.changes += 1

    @property
    def changes(self) -> int:
        """`CommandTable.changes`: moves whenever the pending targets may have changed (an int,
        read without the lock: read it before the targets, and a change after is seen next)."""
        return self.table.changes

    def pending_targets(self, world: int | np.ndarray | slice) -> np.ndarray:
        """Targets as of every command accepted so far (some may not be in effect yet).

        A slice (every world) copies in one block, without the gather a fancy index makes."""
        with self._lock:
            return self.table.pending[world].copy()
