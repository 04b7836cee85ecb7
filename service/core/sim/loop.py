"""SimLoop: owns a WorldBatch on a thread of its own; time, commands and snapshots.

Data flows one way. Commands arrive from any thread and are folded, under one lock, into a
*pending* target table (validated first, so a rejected command changes nothing). At each tick
boundary the loop thread moves what is pending into the engine in one write, steps the tick with
the lock released (the graph replay releases the GIL too), then publishes a snapshot if a sink or
reader wants one. A command takes effect at a tick known when it is accepted: the `tick` in every
reply; the first snapshot whose `tick` is >= it carries the new target.

While paused at rest a write does not wait for a tick that may never come: the loop applies
it at once, between two ticks, and publishes the state it makes (its part `state_door`:
loop_state.py says why that keeps every reply's tick and every recording as they were).
"""

from __future__ import annotations

import concurrent.futures
import logging
import threading
import time
from collections.abc import Callable
from typing import TypeVar

import numpy as np

from service.core.errors import NotPaused
from service.core.process.engine_priority import EnginePriority, Setting
from service.core.sim.batch import Batch, SteppedBeside, TickWrites
from service.core.sim.command_desk import CommandDesk
from service.core.sim.command_share import CommandShare
from service.core.sim.device_turns import DeviceTurns
from service.core.sim.listeners import Listeners
from service.core.sim.loop_state import LoopHooks, StateDoor
from service.core.sim.loop_types import LoopStats, SnapshotSink, resolve, run_request
from service.core.sim.pace import Cadence, FailureLog, RateWindow, prompt_gil
from service.core.sim.safety import SafetyTable
from service.core.sim.snapshot_beside import BesideSnapshot
from service.core.sim.staging import CommandTable, TrajectoryHook
from service.core.sim.types import Mode, Snapshot
from service.core.sim.waiters import Waiters

log = logging.getLogger("armfleet.loop")
T = TypeVar("T")

# Snapshots are taken when a sink wants one, a reader waits for one, or at least this often so
# that `latest` is never older than this (+ a tick: snapshot_beside.py); fresh_snapshot waits.
_IDLE_SNAPSHOT_PERIOD = 0.1


class SimLoop:
    """Advance a Batch in realtime, fast or paused mode and serialise commands into it."""

    def __init__(
        self,
        batch: Batch,
        mode: Mode = Mode.REALTIME,
        sinks: tuple[SnapshotSink, ...] = (),
        priority: Setting = "off",
    ):
        self.batch = batch
        self.spec = batch.spec
        self.safety = SafetyTable(batch.nworld)  # each world's, stamped on every snapshot
        self.listeners = Listeners((self.safety, *sinks))  # sinks, tick and restore listeners
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._mode = Mode(mode)
        self._running = False
        self._thread: threading.Thread | None = None
        # Everything below is guarded by _lock.
        self._table = CommandTable(batch.targets, batch.home_target)  # what commands staged
        # Commands (any thread) fold into the table through the desk; see command_desk.py.
        self.commands = CommandDesk(
            self._lock,
            self._table,
            batch.nworld,
            self._accept_tick,
            lambda: self._tick,
            lambda: self.state_door.settle_soon(),
        )
        self._stepping = False
        self._tick = batch.tick
        self._step_goal = self._tick  # paused mode: run until the tick counter reaches this
        # Work between ticks, `step` futures, readers waiting for a tick (read-your-writes).
        self._waiters = Waiters()
        self._failures = FailureLog()
        self.engine_seconds = 0.0  # wall time in batch.step, all ticks: the rest is the loop's
        self._latest = batch.snapshot()
        self._last_snapshot_wall = 0.0
        self._beside = BesideSnapshot(batch, lambda s: self.listeners.extend(s, batch), self._show)
        self._rate = RateWindow(self._tick, self._mode, batch.tick_dt)
        self._cadence = Cadence(batch.tick_dt)
        self._rested_at = -1  # the tick the sinks were last told time stopped at (`_at_rest`)
        # launches on a device shared with the camera renderer go in turns (device_turns.py)
        self._turns: DeviceTurns = getattr(batch, "device_turns", None) or DeviceTurns()
        self.randomizations = self.commands.randomizations
        # Snapshots taken and restored, paused writes applied at once (loop_state.py).
        hooks = LoopHooks(
            call=self.call,
            publish=self._publish,
            at_rest=self._at_rest,
            tick=lambda: self._tick,
            latest=lambda: self._latest,
            running=lambda: self._running,
            resting=self._resting,
            jump_to=self._jump_to,
        )
        self.state_door = StateDoor(self._wake, self.commands, self._waiters, self.listeners, hooks)
        self.share = CommandShare(batch.tick_dt)  # ticks first: the commands' budget per tick
        # In real time the threads that step run at a raised priority when permitted (`auto`).
        beside = batch.stepping_ids if isinstance(batch, SteppedBeside) else tuple
        self.priority = EnginePriority(priority, beside)

    # -- life cycle -------------------------------------------------------------------------

    def start(self) -> None:
        prompt_gil()  # the sim thread gets the GIL back within 0.5 ms of asking (pace.py)
        self._running = True
        self._thread = threading.Thread(target=self._run, name="armfleet-sim", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        with self._wake:
            self._running = False
            self.share.set_active(False)
            self._wake.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=10)
        self._serve_requests()  # the thread is gone: requests that raced the stop are served here
        self._waiters.cancel_all()

    # -- commands (any thread: `commands`, the desk) ----------------------------------------

    @property
    def _traj(self) -> TrajectoryHook | None:
        return self.commands.traj

    def _accept_tick(self) -> int:
        """The tick whose stepping first uses a command accepted now (lock held)."""
        return self._tick + (2 if self._stepping else 1)

    # -- time control -----------------------------------------------------------------------

    @property
    def mode(self) -> Mode:
        return self._mode

    def set_mode(self, mode: Mode) -> None:
        with self._wake:
            self._mode = Mode(mode)
            self.share.set_active(self._running and self._mode is Mode.REALTIME)
            self._rate.restart(self._tick)
            self.state_door.settle_soon()  # paused: writes accepted before it are applied now
            self._wake.notify_all()
            waiters = self.state_door.stranded()
        for fut in waiters:  # paused: the ticks they waited for will not come
            resolve(fut, self._latest)

    def step(self, ticks: int) -> concurrent.futures.Future[int]:
        """Paused only: advance exactly `ticks`; the future resolves with the tick reached."""
        with self._wake:
            if self._mode is not Mode.PAUSED:
                raise NotPaused(f"step needs mode 'paused' (mode is {self._mode.value!r})")
            self._step_goal = max(self._step_goal, self._tick) + ticks
            fut = self._waiters.steps.add(self._step_goal)
            self._wake.notify_all()
        return fut

    # -- reading ----------------------------------------------------------------------------

    @property
    def tick(self) -> int:
        """Control ticks completed so far."""
        return self._tick

    @property
    def latest(self) -> Snapshot:
        return self._latest

    @property
    def failure(self) -> str | None:
        """Why the last tick failed; None while ticks succeed."""
        return self._failures.why

    def lag(self) -> float:
        """Seconds the realtime schedule is behind the wall clock now (0 in fast and paused
        mode, and while on time). Within a tick it grows to that tick's duration; behind by
        more, the loop is making up ticks, and past `pace.MAX_LAG_S` it gives time up."""
        if self._mode is not Mode.REALTIME or not self._running:
            return 0.0
        return self._cadence.lag()

    def late(self) -> bool:
        """Behind real time by more than `pace.LATE_S` (`Cadence.late`, the one lateness rule):
        work that can wait (the cameras' stream pictures, core/cameras/clock.py) waits, so that
        the ticks catch up before time is lost; the commands' budget shrinks by the same rule."""
        return self._mode is Mode.REALTIME and self._running and self._cadence.late()

    @property
    def stats(self) -> LoopStats:
        if self._mode is Mode.PAUSED:
            return LoopStats(self._tick, self._mode, 0.0, 0.0)
        return self._rate.stats

    # -- between two ticks: work, restores and fresh reads for other threads ---------------

    def call(self, fn: Callable[[Batch], T]) -> concurrent.futures.Future[T]:
        """Run `fn(batch)` on the sim thread between two ticks; the future gets its result.

        The batch belongs to the sim thread, so this is how other threads read or change it. In
        paused mode the request is served at once. Never wait on it from the sim thread itself.
        """
        with self._wake:
            if self._running:
                fut = self._waiters.add_request(fn)
                self._wake.notify_all()
                return fut
        fut = concurrent.futures.Future()
        with self._turns.loop_turn():  # not running: no other thread touches the batch
            run_request(fn, fut, self.batch)
        return fut

    def _serve_requests(self) -> None:
        with self._lock:
            requests = self._waiters.take_requests()
        if requests:
            self._beside.finish()  # shown before anything changes the batch
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
        with self._wake:
            need = self._tick + (1 if self._stepping else 0)
            effective = self._table.effective
            if effective.size:
                chosen = effective if worlds is None else effective[worlds]
                need = max(need, int(chosen.max(initial=0)))
            if self._latest.tick >= need or not self._running or self.state_door.will_not_advance():
                fut: concurrent.futures.Future[Snapshot] = concurrent.futures.Future()
                fut.set_result(self._latest)
            else:
                fut = self._waiters.readers.add(need)
                self._wake.notify_all()  # a paused loop wakes to publish the tick it stopped at
        return fut

    def _resting(self) -> bool:
        """Paused with no tick under way or due (lock held, or the sim thread)."""
        return self._mode is Mode.PAUSED and not self._stepping and self._tick >= self._step_goal

    def _jump_to(self, tick: int) -> None:
        """Time starts again at `tick` (a restore; lock held): counter, step goal, rate."""
        self._tick = self._step_goal = tick
        self._rate.restart(tick)

    # -- the loop thread --------------------------------------------------------------------

    def _run(self) -> None:
        cadence = self._cadence
        cadence.restart()
        turns = self._turns
        while True:
            self.priority.follow(self._mode is Mode.REALTIME)  # a call only when it changes
            with turns.loop_turn():  # the device's launches (service/core/sim/device_turns.py)
                self._serve_requests()
            with self._wake:
                if not self._running:
                    return
                if self._waiters.requests_waiting:  # arrived while serving: serve them first
                    continue
                mode = self._mode
                self.share.set_active(mode is Mode.REALTIME)
                idle = mode is Mode.PAUSED and self._tick >= self._step_goal
                if idle and self._latest.tick >= self._tick and self._rested_at == self._tick:
                    self._wake.wait()
                    cadence.restart()
                    continue
                late = False
                if mode is Mode.REALTIME:
                    delay = cadence.delay()
                    if delay > 0:
                        self._wake.wait(delay)
                        continue
                    late = cadence.late()  # this tick starts late (pace: the one rule)
            if idle:  # paused: show where time stopped, once (a snapshot first if it took none)
                with turns.loop_turn():
                    now = time.monotonic()
                    if self._latest.tick < self._tick:
                        self._publish(now)
                    self._at_rest(now)
                continue
            try:
                with turns.loop_turn():
                    self._tick_once(mode)
            except Exception as exc:  # never let a bad tick kill the loop, nor flood the log
                self._tick_failed(exc)
                time.sleep(0.1)
            else:
                self._failures.succeeded()
            if mode is Mode.REALTIME:
                cadence.ticked()
                self.share.ticked(late)

    def _tick_failed(self, exc: Exception) -> None:
        """Report the failure (pace.FailureLog) and tell the tick listeners."""
        with self._lock:
            self._stepping = False
        self._failures.failed(exc)
        self.listeners.counted(self._tick, 0.0, -1)  # -1: the tick failed

    def _tick_once(self, mode: Mode) -> None:
        """One tick as named stages, each holding the lock only for its own bookkeeping."""
        t0 = time.perf_counter()
        writes = self._take_commands()
        if writes:
            self.batch.write(writes)  # the engines' one door
        t_step = time.perf_counter()
        faulted = self.batch.step(1)
        self.engine_seconds += time.perf_counter() - t_step
        self._beside.finish()  # the last tick's periodic snapshot, copied beside this one
        now = time.monotonic()
        wanted = self._finish_tick(faulted, mode, now)
        periodic = now - self._last_snapshot_wall >= _IDLE_SNAPSHOT_PERIOD
        if wanted or (periodic and not self._beside.start(now)):
            self._publish(now)
        self.listeners.ticked(self.batch, now)
        if mode is Mode.PAUSED and self._tick >= self._step_goal:  # a step burst's last tick
            self._at_rest(now)
        with self._lock:
            stepped = self._waiters.steps.reached(self._tick)
        for fut in stepped:  # the `step` calls whose goal tick this is
            fut.set_result(self._tick)
        self._rate.update(now, self._tick, self._mode)
        seconds = time.perf_counter() - t0
        if self._traj is not None:
            self._traj.dispatch()
        self.listeners.counted(self._tick, seconds, int(faulted.size))

    def _take_commands(self) -> TickWrites:
        """Take what is pending from under the lock as the engine's `TickWrites` (velocity
        None when all zero); running trajectories are sampled first."""
        with self._lock:
            if self._traj is not None:
                self._traj.sample(self._tick + 1, self.commands.view())
            writes = self._table.take()
            self._stepping = True
        return writes

    def _finish_tick(self, faulted: np.ndarray, mode: Mode, now: float) -> bool:
        """Count the tick, forget targets of worlds reset for faults; is a snapshot wanted?"""
        with self._lock:
            self._tick = self.batch.tick
            self._stepping = False
            if faulted.size:
                self._table.faulted(faulted)
            self.state_door.settle_soon()  # a write accepted during the last tick of a burst: now
            traj = self._traj is not None and self._traj.after_step(
                self._tick, faulted, self.commands.view()
            )
            return (
                traj
                or (mode is Mode.PAUSED and self._tick >= self._step_goal)
                or bool(self._waiters.readers)
                or self.listeners.wants_snapshot(now)
            )

    def _publish(self, now: float, settled: bool = False) -> None:
        """Take a snapshot, wake the readers waiting for one, hand it to every sink.
        `settled`: it shows paused writes just applied (readers waited for those)."""
        if self._beside.finish() == self.batch.tick and not settled:
            return  # the periodic snapshot on its way showed this very tick
        snap = self.batch.snapshot()
        self._show(self.listeners.extend(snap, self.batch), now, settled)

    def _show(self, snap: Snapshot, now: float, settled: bool = False) -> None:
        with self._lock:
            self._latest = snap
            self._last_snapshot_wall = now
            if settled:
                self.state_door.shown()
            if self._traj is not None:
                self._traj.observe(snap, self.commands.view())
            ready = self._waiters.readers.reached(snap.tick) + self.state_door.stranded()
        for fut in ready:
            resolve(fut, snap)
        self.listeners.publish(snap)

    def _at_rest(self, now: float) -> None:
        """Tell the sinks that time stopped here (they may stream at a cadence of their own,
        which a burst of steps ends between)."""
        self._rested_at = self.batch.tick
        self.listeners.at_rest(self.batch, now)
