"""The batch's state changed between two ticks, without stepping: the full state taken
(snapshots, recordings), a saved one restored, and a paused loop's writes applied at once.

Why apart from loop.py: each of these changes the batch on the sim thread between two ticks,
touches the loop's bookkeeping (tick, step goal, command table, randomisations, trajectories,
waiters) in a fixed order and publishes the result at the same tick; the loop module stays the
tick. `SimLoop` inherits it: the attributes below are the loop's own.

Paused writes: simulation_interfaces' SetEntityState promises "an instant change", and a paused
loop steps no tick that would apply a write. So while paused at rest, whatever a command stages
(targets, resets, entity poses, parameters, randomisations) goes into the engine at once
(`_settle`), and the state it makes is published, so a read right after sees it. The tick in
the reply is unchanged (the first tick stepped from the written state), and so is what a
recording holds: at any tick boundary everything pending is for the next tick, so applying it
at the boundary or at the start of that tick gives the same state, and replay, which stages
it for that tick, the same states. Trajectories still start with the next step.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

from service.core.sim.batch import Batch
from service.core.sim.loop_types import resolve
from service.core.sim.types import BatchState, Mode

if TYPE_CHECKING:
    from service.core.sim.listeners import Listeners
    from service.core.sim.pace import RateWindow
    from service.core.sim.randomizations import RandomizationBook
    from service.core.sim.staging import CommandTable, TrajectoryHook
    from service.core.sim.types import Snapshot
    from service.core.sim.waiters import Waiters

T = TypeVar("T")


class StateDoor:
    """Taking and restoring the full state of a SimLoop's batch (mixed into SimLoop)."""

    listeners: Listeners
    randomizations: RandomizationBook
    _lock: threading.Lock
    _tick: int
    _step_goal: int
    _table: CommandTable
    _rate: RateWindow
    _waiters: Waiters
    _latest: Snapshot
    _mode: Mode
    _running: bool
    _stepping: bool
    _wake: threading.Condition
    _settle_queued: bool  # a `_settle` request waits in the queue
    _unsettled: bool  # paused writes not yet published: fresh readers wait for them

    if TYPE_CHECKING:  # the loop's own, used here

        @property
        def _traj(self) -> TrajectoryHook | None: ...

        def call(self, fn: Callable[[Batch], T]) -> concurrent.futures.Future[T]: ...

        def _publish(self, now: float, settled: bool = False) -> None: ...

        def _at_rest(self, now: float) -> None: ...

    def request_state(self) -> concurrent.futures.Future[BatchState]:
        """Every world's full state at the next tick boundary (`state_of`)."""
        return self.call(self.state_of)

    def state_of(self, batch: Batch) -> BatchState:
        """`batch.get_state()` with the randomisations it holds (sim thread, or a stopped
        loop): a snapshot's header names them."""
        return dataclasses.replace(batch.get_state(), randomized=self.randomizations.at(batch.tick))

    def restore(self, state: BatchState, name: str = "") -> concurrent.futures.Future[int]:
        """Continue from `state` at the next tick boundary; the future gets the restored tick.

        Commands accepted but not yet applied are dropped (they belonged to the replaced state);
        step requests waiting in paused mode complete at the restored tick. A state that does not
        fit fails the future with ValueError, and nothing changes.
        """
        return self.call(lambda batch: self._restore(batch, state, name))

    def _restore(self, batch: Batch, state: BatchState, name: str) -> int:
        tick_before = batch.tick
        batch.set_state(state)  # checks everything before changing anything
        with self._lock:
            self._tick = batch.tick
            self._step_goal = self._tick
            self._table.restored(batch.targets, self._tick)
            self.randomizations.replace(state.randomized)
            if self._traj is not None:
                self._traj.restored()
            self._rate.restart(self._tick)
            waiting = self._waiters.steps.take()
        self.listeners.restored(tick_before, state, name)
        if self._traj is not None:  # the trajectories the restore stopped, told now
            self._traj.dispatch()
        self._publish(time.monotonic())
        with self._lock:  # readers waiting for a tick of the old timeline get the restored state
            readers = self._waiters.readers.take()
        for reader in readers:
            resolve(reader, self._latest)
        for fut in waiting:
            fut.set_result(self._tick)
        return self._tick

    def _settle_soon(self) -> None:
        """A command was staged (lock held): while paused at rest, apply it now (`_settle`)
        instead of at a step that may never come; one request covers every write before it."""
        if self._mode is not Mode.PAUSED or self._stepping or self._tick < self._step_goal:
            return  # a tick is under way or due: it applies the writes
        if not self._running or not self._table.has_writes():
            return  # not running: nobody reads (fresh_snapshot answers at once)
        self._unsettled = True  # fresh_snapshot's readers wait for the write's state
        if not self._settle_queued:
            self._settle_queued = True
            self._waiters.add_request(self._settle)
            self._wake.notify_all()

    def _settle(self, batch: Batch) -> None:
        """Between two ticks (sim thread): hand what is pending to the engine now, as the next
        tick would have first, and publish it at the same tick. The stepped tick is published
        first if it was not (a recording holds each tick's state as it was stepped)."""
        now = time.monotonic()
        if self._latest.tick < self._tick:
            self._publish(now)
        with self._lock:
            self._settle_queued = False
            writes = self._table.take()
            self.randomizations.hold()  # the state now holds those accepted so far
        if writes:
            batch.write(writes)
        self._publish(now, settled=True)
        if self._mode is Mode.PAUSED and self._tick >= self._step_goal:
            self._at_rest(now)
