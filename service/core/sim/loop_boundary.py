"""The loop's door for other threads between two ticks: work on the batch, and fresh reads.

The batch belongs to the sim thread; other threads hand it work (`call`: read the full state,
restore one) that runs between two ticks, and wait for a snapshot that includes their own
commands (`fresh_snapshot`). `SimLoop` (loop.py) mixes this in; the state it reads and writes
is the loop's own, guarded by the loop's lock.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from service.core.sim.batch import Batch
from service.core.sim.device_turns import DeviceTurns
from service.core.sim.loop_types import RestoreListener, resolve, run_request
from service.core.sim.randomizations import RandomizationBook
from service.core.sim.staging import CommandTable, TrajectoryHook
from service.core.sim.types import BatchState, Mode, Snapshot

log = logging.getLogger("armfleet.loop")
T = TypeVar("T")


class TickBoundary:
    """Work and reads other threads ask of the loop between ticks (mixed into `SimLoop`)."""

    batch: Batch
    _lock: threading.Lock
    _wake: threading.Condition
    _running: bool
    _mode: Mode
    _tick: int
    _step_goal: int
    _stepping: bool
    _table: CommandTable
    _traj: TrajectoryHook | None
    _window: tuple[float, int]
    _latest: Snapshot
    _step_waiters: list[tuple[int, concurrent.futures.Future[int]]]
    _snapshot_waiters: list[tuple[int, concurrent.futures.Future[Snapshot]]]
    _requests: list[tuple[Callable[[Batch], Any], concurrent.futures.Future[Any]]]
    _restore_listeners: tuple[RestoreListener, ...]
    _turns: DeviceTurns
    _publish: Callable[[float], None]
    randomizations: RandomizationBook

    def call(self, fn: Callable[[Batch], T]) -> concurrent.futures.Future[T]:
        """Run `fn(batch)` on the sim thread between two ticks; the future gets its result.

        The batch belongs to the sim thread, so this is how other threads read or change it. In
        paused mode the request is served at once. Never wait on it from the sim thread itself.
        """
        fut: concurrent.futures.Future[T] = concurrent.futures.Future()
        with self._wake:
            if self._running:
                self._requests.append((fn, fut))
                self._wake.notify_all()
                return fut
        with self._turns.loop_turn():  # not running: no other thread touches the batch
            run_request(fn, fut, self.batch)
        return fut

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

    def add_restore_listener(self, listener: RestoreListener) -> None:
        self._restore_listeners = (*self._restore_listeners, listener)

    def remove_restore_listener(self, listener: RestoreListener) -> None:
        self._restore_listeners = tuple(x for x in self._restore_listeners if x is not listener)

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
            self._window = (time.monotonic(), self._tick)
            waiting, self._step_waiters = self._step_waiters, []
        for listener in self._restore_listeners:
            try:
                listener(tick_before, state, name)
            except Exception:
                log.exception("restore listener %r failed", listener)
        if self._traj is not None:  # the trajectories the restore stopped, told now
            self._traj.dispatch()
        self._publish(time.monotonic())
        with self._lock:  # readers waiting for a tick of the old timeline get the restored state
            readers, self._snapshot_waiters = self._snapshot_waiters, []
        for _, reader in readers:
            resolve(reader, self._latest)
        for _, fut in waiting:
            fut.set_result(self._tick)
        return self._tick

    def _serve_requests(self) -> None:
        with self._lock:
            requests, self._requests = self._requests, []
        for fn, fut in requests:
            run_request(fn, fut, self.batch)

    def fresh_snapshot(
        self, worlds: np.ndarray | list[int] | None = None
    ) -> concurrent.futures.Future[Snapshot]:
        """A snapshot that includes every command accepted for `worlds` (all when None) so far.

        Read-your-writes: it waits for the tick from which the latest accepted command of those
        worlds is in effect (at most the tick in progress and the next one while running), and
        never returns a tick older than the last completed one. While paused those ticks do not
        come: the latest snapshot is returned at once and the caller shows `pending_targets`.
        """
        fut: concurrent.futures.Future[Snapshot] = concurrent.futures.Future()
        with self._wake:
            need = self._tick + (1 if self._stepping else 0)
            effective = self._table.effective
            if effective.size:
                chosen = effective if worlds is None else effective[worlds]
                need = max(need, int(chosen.max(initial=0)))
            if self._latest.tick >= need or not self._running or self._will_not_advance():
                fut.set_result(self._latest)
            else:
                self._snapshot_waiters.append((need, fut))
                self._wake.notify_all()  # a paused loop wakes to publish the tick it stopped at
        return fut

    def _release_step_waiters(self) -> None:
        """Resolve the `step` futures whose goal tick has been reached (sim thread)."""
        with self._lock:
            done = [f for g, f in self._step_waiters if g <= self._tick]
            self._step_waiters = [(g, f) for g, f in self._step_waiters if g > self._tick]
        for fut in done:
            fut.set_result(self._tick)

    def _will_not_advance(self) -> bool:
        """Paused with no step requested, no tick in progress, and `latest` showing the last
        tick (lock held). Realtime does not snapshot every tick, so a pause can find `latest`
        behind: the sim thread then publishes once more, and readers wait for that."""
        return (
            self._mode is Mode.PAUSED
            and self._tick >= self._step_goal
            and not self._stepping
            and self._latest.tick >= self._tick
        )

    def _stranded_waiters(self) -> list[concurrent.futures.Future[Snapshot]]:
        """Readers whose tick will not come because time stands still (lock held)."""
        if not self._will_not_advance():
            return []
        stranded = [f for _, f in self._snapshot_waiters]
        self._snapshot_waiters = []
        return stranded
