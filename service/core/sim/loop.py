"""SimLoop: owns a WorldBatch on a thread of its own; time, commands and snapshots.

Data flows one way. Commands arrive from any thread and are folded, under one lock, into a
*pending* target table (validated first, so a rejected command changes nothing). At each tick
boundary the loop thread moves what is pending into the engine in one write, steps the tick with
the lock released (the graph replay releases the GIL too), then publishes a snapshot if a sink or
reader wants one. A command takes effect at a tick known when it is accepted: the `tick` in every
reply; the first snapshot whose `tick` is >= it carries the new target.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from service.core.errors import NotPaused
from service.core.sim.arithmetic import TargetUpdate
from service.core.sim.batch import Batch, ModelWrite, StateWrite, TickWrites
from service.core.sim.device_turns import DeviceTurns
from service.core.sim.loop_boundary import TickBoundary
from service.core.sim.loop_types import (  # re-exported: the loop's vocabulary
    CommandResult,
    LoopStats,
    RestoreListener,
    SnapshotSink,
    TickListener,
    resolve,
)
from service.core.sim.randomizations import RandomizationBook, Randomized
from service.core.sim.staging import CommandTable, Override, Staging, TrajectoryHook
from service.core.sim.types import Mode, Snapshot

log = logging.getLogger("armfleet.loop")

# Snapshots are taken when a sink wants one, a reader waits for one, or at least this often so
# that `latest` is never older than this; readers that need the current tick ask for one.
_IDLE_SNAPSHOT_PERIOD = 0.1
_MAX_LAG_S = 0.1  # real time catches up after hiccups (a shared core paused) up to this far
_STATS_WINDOW = 1.0  # seconds of wall time over which ticks/s and real-time factor are measured


class SimLoop(TickBoundary):
    """Advance a Batch in realtime, fast or paused mode and serialise commands into it."""

    def __init__(
        self,
        batch: Batch,
        mode: Mode = Mode.REALTIME,
        sinks: tuple[SnapshotSink, ...] = (),
    ):
        self.batch = batch
        self.spec = batch.spec
        self._sinks = tuple(sinks)  # replaced, never mutated: read by the sim thread
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._mode = Mode(mode)
        self._running = False
        self._thread: threading.Thread | None = None
        # Everything below is guarded by _lock.
        self._table = CommandTable(batch.targets, batch.home_target)  # what commands staged
        self._traj: TrajectoryHook | None = None
        self._stepping = False
        self._tick = batch.tick
        self._step_goal = self._tick  # paused mode: run until the tick counter reaches this
        self._step_waiters: list[tuple[int, concurrent.futures.Future[int]]] = []
        # Readers waiting for a snapshot of at least this tick (read-your-writes).
        self._snapshot_waiters: list[tuple[int, concurrent.futures.Future[Snapshot]]] = []
        self._tick_listeners: tuple[TickListener, ...] = ()
        self.failure: str | None = None  # why the last tick failed; None while ticks succeed
        self.engine_seconds = 0.0  # wall time in batch.step, all ticks: the rest is the loop's
        self._latest = batch.snapshot()
        self._last_snapshot_wall = 0.0
        self._stats = LoopStats(self._tick, self._mode, 0.0, 0.0)
        self._window: tuple[float, int] = (time.monotonic(), self._tick)
        # Work for the sim thread between two ticks (state, restore, reads of the batch).
        self._requests: list[tuple[Callable[[Batch], Any], concurrent.futures.Future[Any]]] = []
        # launches on a device shared with the camera renderer go in turns (device_turns.py)
        self._turns: DeviceTurns = getattr(batch, "device_turns", None) or DeviceTurns()
        self._restore_listeners: tuple[RestoreListener, ...] = ()
        # Per world, the last randomisation (seed, spec) and its tick: snapshots name it.
        self.randomizations = RandomizationBook()

    # -- life cycle -------------------------------------------------------------------------

    def start(self) -> None:
        self._running = True
        self._thread = threading.Thread(target=self._run, name="armfleet-sim", daemon=True)
        self._thread.start()

    def add_sink(self, sink: SnapshotSink) -> None:
        """Also publish snapshots to `sink` (from the next tick on)."""
        self._sinks = (*self._sinks, sink)

    def remove_sink(self, sink: SnapshotSink) -> None:
        self._sinks = tuple(s for s in self._sinks if s is not sink)

    def stop(self) -> None:
        with self._wake:
            self._running = False
            self._wake.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=10)
        self._serve_requests()  # the thread is gone: requests that raced the stop are served here
        for _, fut in (*self._step_waiters, *self._snapshot_waiters):
            fut.cancel()

    # -- commands (any thread) --------------------------------------------------------------

    def _accept_tick(self) -> int:
        """The tick whose stepping first uses a command accepted now (lock held)."""
        return self._tick + (2 if self._stepping else 1)

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
            out = self._table.stage_rows(worlds, update, self._accept_tick())
            if self._traj is not None and out:
                self._traj.overridden(np.asarray(worlds), Override.MANUAL, named)
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
        idx = np.arange(self.batch.nworld) if worlds is None else np.asarray(worlds, dtype=int)
        with self._lock:
            tick = self._accept_tick()
            self._table.stage_reset(idx, tick)
            if writes:
                self._table.stage_state(writes, tick)
            if randomized is not None:
                entry = Randomized(tick, *randomized)
                self.randomizations.record(idx.tolist(), entry, self._tick)
            if self._traj is not None:
                self._traj.overridden(idx, Override.RESET)
            return tick

    def stage_state(self, writes: Sequence[StateWrite | ModelWrite]) -> int:
        """Stage qpos/qvel slices or per-world model values (validated by their command) for
        the next tick boundary, after that boundary's resets; the tick they take effect at."""
        with self._lock:
            tick = self._accept_tick()
            self._table.stage_state(writes, tick)
            return tick

    def attach_trajectories(self, hook: TrajectoryHook) -> None:
        """Let `hook` run trajectories: it is called at every stage of a tick (see staging)."""
        self._traj = hook

    @contextlib.contextmanager
    def staging(self, worlds: np.ndarray | None = None) -> Iterator[Staging]:
        """Hold the command lock and lend the pending tables; `worlds` get the effective tick."""
        with self._lock:
            st = self._staged()
            yield st
            if worlds is not None:
                self._table.effective[worlds] = st.tick

    def pending_targets(self, world: int | np.ndarray) -> np.ndarray:
        """Targets as of every command accepted so far (some may not be in effect yet)."""
        with self._lock:
            return self._table.pending[world].copy()

    # -- time control -----------------------------------------------------------------------

    @property
    def mode(self) -> Mode:
        return self._mode

    def set_mode(self, mode: Mode) -> None:
        with self._wake:
            self._mode = Mode(mode)
            self._window = (time.monotonic(), self._tick)
            self._wake.notify_all()
            waiters = self._stranded_waiters()
        for fut in waiters:  # paused: the ticks they waited for will not come
            resolve(fut, self._latest)

    def step(self, ticks: int) -> concurrent.futures.Future[int]:
        """Paused only: advance exactly `ticks`; the future resolves with the tick reached."""
        fut: concurrent.futures.Future[int] = concurrent.futures.Future()
        with self._wake:
            if self._mode is not Mode.PAUSED:
                raise NotPaused(f"step needs mode 'paused' (mode is {self._mode.value!r})")
            self._step_goal = max(self._step_goal, self._tick) + ticks
            self._step_waiters.append((self._step_goal, fut))
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

    def add_tick_listener(self, listener: TickListener) -> None:
        """Call `listener(tick, seconds, faulted_count)` on the sim thread after every tick.

        For counters (metrics): it must be quick and must not block.
        """
        self._tick_listeners = (*self._tick_listeners, listener)

    @property
    def stats(self) -> LoopStats:
        if self._mode is Mode.PAUSED:
            return LoopStats(self._tick, self._mode, 0.0, 0.0)
        return self._stats

    # -- the loop thread --------------------------------------------------------------------

    def _run(self) -> None:
        next_deadline = time.perf_counter()
        turns = self._turns
        while True:
            with turns.loop_turn():  # the device's launches (service/core/sim/device_turns.py)
                self._serve_requests()
            with self._wake:
                if not self._running:
                    return
                if self._requests:  # arrived while serving: serve before waiting or stepping
                    continue
                mode = self._mode
                idle = mode is Mode.PAUSED and self._tick >= self._step_goal
                if idle and self._latest.tick >= self._tick:
                    self._wake.wait()
                    next_deadline = time.perf_counter()
                    continue
                if mode is Mode.REALTIME:
                    delay = next_deadline - time.perf_counter()
                    if delay > 0:
                        self._wake.wait(delay)
                        continue
            if idle:  # paused after a tick that took no snapshot: show where time stopped
                with turns.loop_turn():
                    self._publish(time.monotonic())
                    self._at_rest(time.monotonic())
                continue
            try:
                with turns.loop_turn():
                    self._tick_once(mode)
            except Exception as exc:  # never let a bad tick kill the loop, nor flood the log
                self._tick_failed(exc)
                time.sleep(0.1)
            else:
                if self.failure is not None:
                    log.warning("ticks succeed again after: %s", self.failure)
                    self.failure = None
            if mode is Mode.REALTIME:
                # Keep the cadence: overrun ticks are made up at once, up to _MAX_LAG_S (or
                # one tick) behind; further behind, time is given up (the RTF shows it).
                next_deadline += self.batch.tick_dt
                now = time.perf_counter()
                if now - next_deadline > max(self.batch.tick_dt, _MAX_LAG_S):
                    next_deadline = now

    def _tick_failed(self, exc: Exception) -> None:
        """Log the first failure with its traceback, then stay quiet until ticks succeed."""
        with self._lock:
            self._stepping = False
        why = f"{type(exc).__name__}: {exc}"
        if self.failure is None:
            log.error("tick failed; the service is not ready until ticks succeed", exc_info=exc)
        elif why != self.failure:
            log.error("tick still failing, now with: %s", why)
        self.failure = why
        for listener in self._tick_listeners:
            with contextlib.suppress(Exception):
                listener(self._tick, 0.0, -1)  # -1: the tick failed

    def _tick_once(self, mode: Mode) -> None:
        """One tick as named stages, each holding the lock only for its own bookkeeping."""
        t0 = time.perf_counter()
        writes = self._take_commands()
        if writes:
            self.batch.write(writes)  # the engines' one door
        t_step = time.perf_counter()
        faulted = self.batch.step(1)
        self.engine_seconds += time.perf_counter() - t_step
        now = time.monotonic()
        if self._finish_tick(faulted, mode, now):
            self._publish(now)
        for sink in self._sinks:  # sinks need not subclass SnapshotSink: on_tick is optional
            if (on_tick := getattr(sink, "on_tick", None)) is not None:
                on_tick(self.batch, now)
        if mode is Mode.PAUSED and self._tick >= self._step_goal:  # a step burst's last tick
            self._at_rest(now)
        self._release_step_waiters()
        self._update_stats(now)
        seconds = time.perf_counter() - t0
        if self._traj is not None:
            self._traj.dispatch()
        for listener in self._tick_listeners:
            try:
                listener(self._tick, seconds, int(faulted.size))
            except Exception:
                log.exception("tick listener %r failed", listener)

    def _take_commands(self) -> TickWrites:
        """Take what is pending from under the lock as the engine's `TickWrites` (velocity
        None when all zero); running trajectories are sampled first."""
        with self._lock:
            if self._traj is not None:
                self._traj.sample(self._tick + 1, self._staged())
            writes = self._table.take()
            self._stepping = True
        return writes

    def _staged(self) -> Staging:
        """The pending tables for the hook (lock held)."""
        return self._table.view(self._accept_tick())

    def _finish_tick(self, faulted: np.ndarray, mode: Mode, now: float) -> bool:
        """Count the tick, forget targets of worlds reset for faults; is a snapshot wanted?"""
        with self._lock:
            self._tick = self.batch.tick
            self._stepping = False
            if faulted.size:
                self._table.faulted(faulted)
            traj = self._traj is not None and self._traj.after_step(
                self._tick, faulted, self._staged()
            )
            return (
                traj
                or (mode is Mode.PAUSED and self._tick >= self._step_goal)
                or bool(self._snapshot_waiters)
                or now - self._last_snapshot_wall >= _IDLE_SNAPSHOT_PERIOD
                or any(sink.wants_snapshot(now) for sink in self._sinks)
            )

    def _publish(self, now: float) -> None:
        """Take a snapshot, wake the readers waiting for one, hand it to every sink."""
        snap = self.batch.snapshot()
        for sink in self._sinks:  # what a sink's clients asked for besides (the hub: entities)
            if (extend := getattr(sink, "extend_snapshot", None)) is not None:
                snap = extend(snap, self.batch)
        with self._lock:
            self._latest = snap
            self._last_snapshot_wall = now
            if self._traj is not None:
                self._traj.observe(snap, self._staged())
            ready = [f for need, f in self._snapshot_waiters if need <= snap.tick]
            self._snapshot_waiters = [(n, f) for n, f in self._snapshot_waiters if n > snap.tick]
            ready += self._stranded_waiters()
        for fut in ready:
            resolve(fut, snap)
        for sink in self._sinks:
            sink.publish(snap)

    def _at_rest(self, now: float) -> None:
        """Tell the sinks that time stopped here (they may stream at a cadence of their own,
        which a burst of steps ends between)."""
        for sink in self._sinks:
            if (at_rest := getattr(sink, "at_rest", None)) is not None:
                at_rest(self.batch, now)

    def _update_stats(self, now: float) -> None:
        t0, tick0 = self._window
        if now - t0 < _STATS_WINDOW:
            return
        rate = (self._tick - tick0) / (now - t0)
        self._stats = LoopStats(self._tick, self._mode, rate, rate * self.batch.tick_dt)
        self._window = (now, self._tick)
