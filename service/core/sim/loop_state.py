"""The batch's state changed between two ticks, without stepping: the full state taken
(snapshots, recordings), a saved one restored, and a paused loop's writes applied at once.

Why a part of its own (`SimLoop.state_door`): each of these changes the batch on the sim thread
between two ticks, touches the loop's bookkeeping (tick, step goal, command table,
randomisations, trajectories, waiters) in a fixed order and publishes the result at the same
tick; the loop module stays the tick. The door keeps its own state (a paused write queued, or
applied but not yet shown) and holds the parts it shares with the loop (the lock, the command
desk, the waiters, the listeners); what stays the loop's (its tick counter, publishing) it
reaches through `LoopHooks`, which the loop hands it.

Paused writes: simulation_interfaces' SetEntityState promises "an instant change", and a paused
loop steps no tick that would apply a write. So while paused at rest, whatever a command stages
(targets, resets, entity poses, parameters, randomisations) goes into the engine at once
(`_settle`), and the state it makes is published, so a read right after sees it. The tick in
the reply is unchanged (the first tick stepped from the written state), and so is what a
recording holds: at any tick boundary everything pending is for the next tick, so applying it
at the boundary or at the start of that tick gives the same state, and replay, which stages
it for that tick, the same states. Trajectories still start with the next step. A reader
waiting for a newer snapshot is answered at once when no tick will come (`will_not_advance`),
unless a paused write is still on its way: it waits for the state that write makes.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import threading
import time
from collections.abc import Callable
from typing import Any

from service.core.sim.batch import Batch
from service.core.sim.command_desk import CommandDesk
from service.core.sim.listeners import Listeners
from service.core.sim.loop_types import resolve
from service.core.sim.types import BatchState, Snapshot
from service.core.sim.waiters import Waiters


@dataclasses.dataclass(frozen=True)
class LoopHooks:
    """What stays the loop's, lent to its state door (SimLoop passes its own)."""

    call: Callable[[Callable[[Batch], Any]], concurrent.futures.Future[Any]]  # between ticks
    publish: Callable[[float, bool], None]  # a snapshot now; True: it shows paused writes
    at_rest: Callable[[float], None]  # tell the sinks time stopped at the batch's tick
    tick: Callable[[], int]  # the last tick completed
    latest: Callable[[], Snapshot]  # the snapshot published last
    running: Callable[[], bool]  # the sim thread runs
    resting: Callable[[], bool]  # paused, no tick under way or due (lock held)
    jump_to: Callable[[int], None]  # the loop's time starts again at a tick (lock held)


class StateDoor:
    """Taking and restoring the full state of a SimLoop's batch; while it is paused at rest,
    applying writes at once and answering the readers whose tick will not come."""

    def __init__(
        self,
        wake: threading.Condition,
        desk: CommandDesk,
        waiters: Waiters,
        listeners: Listeners,
        loop: LoopHooks,
    ) -> None:
        self._wake = wake  # the loop's lock, as its condition: the sim thread waits on it
        self._desk = desk  # the command table, randomisations and trajectories it stages
        self._waiters = waiters
        self._listeners = listeners
        self._loop = loop
        self._settle_queued = False  # a `_settle` request waits in the queue (lock held)
        self.unsettled = False  # paused writes not yet published: fresh readers wait for them

    # -- the full state ----------------------------------------------------------------------

    def request_state(self) -> concurrent.futures.Future[BatchState]:
        """Every world's full state at the next tick boundary (`state_of`)."""
        return self._loop.call(self.state_of)

    def state_of(self, batch: Batch) -> BatchState:
        """`batch.get_state()` with the randomisations it holds (sim thread, or a stopped
        loop): a snapshot's header names them."""
        held = self._desk.randomizations.at(batch.tick)
        return dataclasses.replace(batch.get_state(), randomized=held)

    def restore(self, state: BatchState, name: str = "") -> concurrent.futures.Future[int]:
        """Continue from `state` at the next tick boundary; the future gets the restored tick.

        Commands accepted but not yet applied are dropped (they belonged to the replaced state);
        step requests waiting in paused mode complete at the restored tick. A state that does not
        fit fails the future with ValueError, and nothing changes.
        """
        return self._loop.call(lambda batch: self._restore(batch, state, name))

    def _restore(self, batch: Batch, state: BatchState, name: str) -> int:
        tick_before = batch.tick
        batch.set_state(state)  # checks everything before changing anything
        tick, traj = batch.tick, self._desk.traj
        with self._wake:
            self._loop.jump_to(tick)
            self._desk.table.restored(batch.targets, tick)
            self._desk.randomizations.replace(state.randomized)
            if traj is not None:
                traj.restored()
            waiting = self._waiters.steps.take()
        self._listeners.restored(tick_before, state, name)
        if traj is not None:  # the trajectories the restore stopped, told now
            traj.dispatch()
        self._loop.publish(time.monotonic(), False)
        with self._wake:  # readers waiting for a tick of the old timeline get the restored state
            readers = self._waiters.readers.take()
        latest = self._loop.latest()
        for reader in readers:
            resolve(reader, latest)
        for fut in waiting:
            fut.set_result(tick)
        return tick

    # -- paused at rest: writes applied at once, readers answered at once ----------------------

    def settle_soon(self) -> None:
        """A command was staged (lock held): while paused at rest, apply it now (`_settle`)
        instead of at a step that may never come; one request covers every write before it."""
        if not self._loop.resting():
            return  # a tick is under way or due: it applies the writes
        if not self._loop.running() or not self._desk.table.has_writes():
            return  # not running: nobody reads (fresh_snapshot answers at once)
        self.unsettled = True  # fresh_snapshot's readers wait for the write's state
        if not self._settle_queued:
            self._settle_queued = True
            self._waiters.add_request(self._settle)
            self._wake.notify_all()

    def will_not_advance(self) -> bool:
        """Paused with no step requested, no tick in progress, and `latest` showing the last
        tick (lock held), with no paused write still to apply. Realtime does not snapshot every
        tick, so a pause can find `latest` behind: the sim thread then publishes once more, and
        readers wait for that."""
        loop = self._loop
        return loop.resting() and loop.latest().tick >= loop.tick() and not self.unsettled

    def stranded(self) -> list[concurrent.futures.Future[Snapshot]]:
        """Readers whose tick will not come because time stands still (lock held)."""
        return self._waiters.readers.take() if self.will_not_advance() else []

    def shown(self) -> None:
        """A snapshot showing the paused writes applied so far was published (lock held)."""
        if not self._settle_queued:
            self.unsettled = False

    def _settle(self, batch: Batch) -> None:
        """Between two ticks (sim thread): hand what is pending to the engine now, as the next
        tick would have first, and publish it at the same tick. The stepped tick is published
        first if it was not (a recording holds each tick's state as it was stepped)."""
        now = time.monotonic()
        if self._loop.latest().tick < batch.tick:
            self._loop.publish(now, False)
        with self._wake:
            self._settle_queued = False
            writes = self._desk.table.take()
            self._desk.randomizations.hold()  # the state now holds those accepted so far
        if writes:
            batch.write(writes)
        self._loop.publish(now, True)
        if self._loop.resting():
            self._loop.at_rest(now)
