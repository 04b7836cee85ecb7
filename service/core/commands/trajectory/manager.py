"""TrajectoryManager: runs JointTrajectories in the loop, one per world, and reports outcomes.

The manager is the loop's trajectory hook (see `SimLoop.attach_trajectories`). Every method
marked *lock held* runs on the sim thread (or a command caller) with the loop's command lock
held, through `SimLoop.staging()`; that one lock orders trajectories against manual commands,
so "a button press after the trajectory stops it" means after in acceptance order.

Per tick (sim thread): `sample` writes every running trajectory's desired positions and
velocity feed-forward into the loop's pending tables (one vectorised pass, `TrajectoryTable`);
`after_step` aborts trajectories of faulted worlds and asks for a snapshot of the tick while any
tolerance is checked or any trajectory has reached its end; `observe`, on that snapshot, records
feedback, checks tolerances and finishes what reached its end. Outcomes are handed to listeners
and futures by `dispatch`, outside the lock.

An aborted or cancelled trajectory holds: the world keeps the last desired position as its
target, with zero velocity feed-forward. A manual command on one of its joints aborts it (one
on other joints, e.g. the gripper's, does not); so do a reset and a restore.
Everything is a function of ticks and simulated state, so a recording replays it exactly.
"""

from __future__ import annotations

import concurrent.futures
import itertools
import logging
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from service.core.commands.trajectory.spec import JointTrajectorySpec
from service.core.commands.trajectory.status import (
    AbortReason,
    Resumable,
    Started,
    TrajectoryState,
    TrajectoryStatus,
    tolerance_detail,
)
from service.core.commands.trajectory.table import TrajectoryTable
from service.core.sim.loop import SimLoop
from service.core.sim.staging import Override, Staging
from service.core.sim.types import Snapshot

log = logging.getLogger("armfleet.trajectory")
Listener = Callable[[TrajectoryStatus], None]
_KEEP_FINISHED = 100_000  # finished trajectories kept for GET and waiters (oldest dropped)


@dataclass
class _Run:
    """A trajectory's bookkeeping (the table holds what is sampled)."""

    id: int
    world: int
    spec: JointTrajectorySpec
    source: str
    start_tick: int
    end_tick: int
    status: TrajectoryStatus
    waiters: list[concurrent.futures.Future[TrajectoryStatus]] = field(default_factory=list)


class TrajectoryManager:
    """Start, cancel and watch trajectories on the worlds of one SimLoop (thread-safe)."""

    def __init__(self, loop: SimLoop) -> None:
        self.loop = loop
        self.spec = loop.spec
        self.table = TrajectoryTable(loop.batch.tick_dt)
        self._ids = itertools.count(1)
        self._runs: dict[int, _Run] = {}  # running, by id
        self._finished: OrderedDict[int, _Run] = OrderedDict()
        self._by_world: dict[int, int] = {}  # world → id of its latest trajectory
        self._done: list[_Run] = []  # finished under the lock, dispatched outside it
        self._listeners: tuple[Listener, ...] = ()
        self._last = np.zeros((0, 7))  # the last sample's desired positions, by slot
        self._last_vel = np.zeros((0, 7))
        self._last_tick = -1
        # The last observed tick: (tick, trajectory id per slot, desired, actual) (S, 7).
        self._feedback = (-1, np.zeros(0, dtype=np.int64), np.zeros((0, 7)), np.zeros((0, 7)))
        self._dispatching = threading.Lock()
        loop.commands.attach_trajectories(self)

    # -- the API (any thread) ---------------------------------------------------------------

    def start(
        self,
        worlds: Sequence[int],
        spec: JointTrajectorySpec,
        source: str,
        dispatch: bool = True,
    ) -> list[Started]:
        """Run `spec` on every world of `worlds` (valid ids) from the same tick.

        Each starts from its world's current target (and velocity feed-forward, when a running
        trajectory is preempted, which is then aborted with reason `preempted`). `dispatch`:
        tell the preempted ones' listeners now (False: the caller calls `dispatch` later,
        e.g. after releasing a lock of its own).
        """
        ids = np.asarray(worlds, dtype=np.int64)
        with self.loop.commands.staging(ids) as st:
            out = self._install(st, ids, spec, source, st.tick, st.pending[ids], st.velocity[ids])
        if dispatch:
            self.dispatch()
        return out

    def resume(self, run: Resumable, source: str) -> tuple[Started, int]:
        """Put back a trajectory that was running when a state was saved (recordings: the
        replay installs what ran at its start tick), sampled exactly as it was from then on.
        Returns it and the tick it is sampled again from."""
        world = np.array([run.world], dtype=np.int64)
        with self.loop.commands.staging(world) as st:
            pos, vel = np.array([run.target]), np.array([run.velocity])
            (started,) = self._install(st, world, run.spec, source, run.start_tick, pos, vel)
        return started, st.tick  # a preempted one is told at the next `dispatch`

    def running(self) -> list[Resumable]:
        """What `resume` needs to put back every running trajectory (take it at a boundary)."""
        with self.loop.commands.staging() as _:
            t = self.table
            return [
                Resumable(int(w), self._runs[i].spec, int(s), p.tolist(), v.tolist())
                for w, i, s, p, v in zip(
                    t.worlds, t.ids.tolist(), t.start_tick, *t.start_rows(), strict=True
                )
            ]

    def _install(
        self,
        st: Staging,
        ids: np.ndarray,
        spec: JointTrajectorySpec,
        source: str,
        start_tick: int,
        start_pos: np.ndarray,
        start_vel: np.ndarray,
    ) -> list[Started]:
        """Preempt what runs on `ids`, then add one slot each (lock held)."""
        self._abort(st, ids, AbortReason.PREEMPTED, "a newer trajectory replaced it")
        traj_ids = np.array([next(self._ids) for _ in range(len(ids))], dtype=np.int64)
        end = self.table.add(traj_ids, ids, spec, start_tick, start_pos, start_vel)
        out = []
        for traj_id, w in zip(traj_ids.tolist(), ids.tolist(), strict=True):
            status = TrajectoryStatus.started(traj_id, w, spec, source, start_tick, end)
            self._runs[traj_id] = _Run(traj_id, w, spec, source, start_tick, end, status)
            self._by_world[w] = traj_id
            out.append(Started(traj_id, w, start_tick, end))
        return out

    def cancel(self, worlds: Sequence[int], dispatch: bool = True) -> list[TrajectoryStatus]:
        """Stop the running trajectories of `worlds` and hold; the statuses of those stopped."""
        ids = np.asarray(worlds, dtype=np.int64)
        with self.loop.commands.staging(ids) as st:
            stopped = self._abort(st, ids, AbortReason.CANCELLED, "cancelled by request")
        if dispatch:
            self.dispatch()
        return [r.status for r in stopped]

    def status(self, world: int) -> TrajectoryStatus | None:
        """The world's running trajectory, else its last one (None if it never ran one)."""
        traj_id = self._by_world.get(world)
        return None if traj_id is None else self.get(traj_id)

    def get(self, traj_id: int) -> TrajectoryStatus | None:
        """A trajectory's status by id (None when unknown or long forgotten)."""
        with self.loop.commands.staging() as _:
            run = self._runs.get(traj_id)
            if run is not None:
                return self._live(run)
            run = self._finished.get(traj_id)
            return None if run is None else run.status

    def brief(self, world: int) -> dict[str, Any] | None:
        """id, state, reason and progress of the world's running (else last) trajectory."""
        status = self.status(world)
        return None if status is None else status.brief()

    def briefs(self, worlds: np.ndarray) -> dict[str, dict[str, Any]]:
        """`brief` of the `worlds` that ran a trajectory, by world id (str), in one pass."""
        out: dict[str, dict[str, Any]] = {}
        if not self._by_world:  # no trajectory has run: nothing to say, every frame, no lock
            return out  # (a dict's truth is read whole; one starting now shows in the next)
        with self.loop.commands.staging() as _:
            t = self.table
            elapsed = (max(self._last_tick, 0) - t.start_tick + 1) * t.tick_dt
            progress = np.clip(elapsed / np.maximum(t.duration, 1e-9), 0.0, 1.0)
            pairs = zip(t.ids.tolist(), progress.tolist(), strict=True)
            running = dict(zip(t.worlds.tolist(), pairs, strict=True))
            known = np.intersect1d(np.fromiter(self._by_world, dtype=np.int64), worlds)
            for w in known.tolist():
                if w in running:
                    traj_id, p = running[w]
                    out[str(w)] = {"id": traj_id, "state": "running", "reason": None, "progress": p}
                elif (run := self._finished.get(self._by_world[w])) is not None:
                    out[str(w)] = run.status.brief()
        return out

    def wait(self, traj_id: int) -> concurrent.futures.Future[TrajectoryStatus]:
        """A future that gets the trajectory's final status (at once if it has finished)."""
        fut: concurrent.futures.Future[TrajectoryStatus] = concurrent.futures.Future()
        with self.loop.commands.staging() as _:
            run = self._runs.get(traj_id)
            if run is not None:
                run.waiters.append(fut)
                return fut
        done = self.get(traj_id)
        if done is None:
            fut.set_exception(KeyError(traj_id))
        else:
            fut.set_result(done)
        return fut

    def add_listener(self, listener: Listener) -> None:
        """Call `listener(status)` once per trajectory when it finishes (any thread; be quick)."""
        self._listeners = (*self._listeners, listener)

    def remove_listener(self, listener: Listener) -> None:
        self._listeners = tuple(x for x in self._listeners if x is not listener)

    # -- the loop's hook (lock held) --------------------------------------------------------

    def overridden(
        self, worlds: np.ndarray, reason: Override, joints: np.ndarray | None = None
    ) -> None:
        """A command naming `joints` (None: a reset) was staged: trajectories driving one
        stop; others go on (a gripper command leaves an arm trajectory running, as on a UR)."""
        if len(self.table):
            why = "a reset" if reason is Override.RESET else "a manual target command"
            worlds = np.asarray(worlds, dtype=np.int64)
            if joints is not None:
                worlds = self.table.worlds[self.table.slots_driving(worlds, joints)]
            self._abort(None, worlds, AbortReason(reason.value), f"stopped by {why}")

    def sample(self, tick: int, st: Staging) -> None:
        """Write the desired state of tick `tick` into the pending tables for every slot."""
        if not len(self.table):
            return
        s = self.table.sample(tick)
        w, driven = self.table.worlds, self.table.driven()
        # Only the driven joints: others keep their staged targets (this tick's included).
        st.pending[w] = np.where(driven, s.positions, st.pending[w])
        st.velocity[w] = np.where(driven, s.velocities, st.velocity[w])
        st.dirty[w] = True
        self.loop.commands.wrote()  # staged through the view: the loop's `take` looks
        self._last, self._last_vel, self._last_tick = s.positions, s.velocities, tick

    def after_step(self, tick: int, faulted: np.ndarray, st: Staging) -> bool:
        """After tick `tick`: abort faulted worlds' runs; is a snapshot of the tick needed?

        Vectorised over slots: no per-trajectory Python work unless one finishes.
        """
        if not len(self.table):
            return False
        if faulted.size:
            self._abort(st, faulted, AbortReason.FAULT, "the world's physics failed; reset")
            st.velocity[faulted] = 0.0
        t = self.table
        # Ended runs finish in `observe`, on this tick's snapshot, so their final status
        # carries the feedback of the end tick.
        return bool(t.has_path.any() or (tick >= t.end_tick).any())

    def observe(self, snap: Snapshot, st: Staging) -> None:
        """Feedback and tolerance checks against the snapshot of the tick last sampled.

        Only the slots that tick sampled are judged (the first len(_last): slots are appended
        at the end and removed from both), so a trajectory started meanwhile never shifts
        the check by a tick: the outcome is the same live and in a replay."""
        t, n = self.table, len(self._last)
        if not n or snap.tick != self._last_tick:
            return
        worlds, ids = t.worlds[:n], t.ids[:n]
        path_tol, goal_tol = t.path_tol[:n], t.goal_tol[:n]
        actual, vel = snap.position[worlds], snap.velocity[worlds]
        err = np.abs(np.stack([actual - self._last, vel - self._last_vel], axis=1))
        self._feedback = (snap.tick, ids.copy(), self._last.copy(), actual.astype(np.float64))
        running = snap.tick < t.end_tick[:n]
        path_bad = running[:, None, None] & (err > path_tol)
        goal_in = (err <= goal_tol).all(axis=(1, 2))  # all true without a goal tolerance
        settling = ~running
        late = settling & t.has_goal[:n] & ~goal_in & (snap.tick >= t.goal_deadline[:n])
        names = self.spec.names
        path = AbortReason.PATH_TOLERANCE, path_tol, "path"
        goal = AbortReason.GOAL_TOLERANCE, goal_tol, "goal"
        aborts = [
            (int(worlds[i]), why, tolerance_detail(names, err[i], tol[i], kind))
            for bad, (why, tol, kind) in ((path_bad.any(axis=(1, 2)), path), (late, goal))
            for i in np.flatnonzero(bad)
        ]
        self._succeed(st, worlds[settling & goal_in], snap.tick)
        for world, reason, detail in aborts:
            self._abort(st, np.array([world]), reason, detail)

    def restored(self) -> None:
        """The whole batch was restored from a saved state: every trajectory stops."""
        self._abort(None, self.table.worlds.copy(), AbortReason.RESET, "the batch was restored")

    def dispatch(self) -> None:
        """Hand finished trajectories to waiters and listeners (no lock held)."""
        if not self._done:  # every command calls this; most find none and take no lock (a run
            return  # finishing meanwhile is handed at the loop's next dispatch, every tick)
        with self._dispatching:
            with self.loop.commands.staging() as _:
                done, self._done = self._done, []
            for run in done:
                for fut in run.waiters:
                    if not fut.done():
                        fut.set_result(run.status)
                for listener in self._listeners:
                    try:
                        listener(run.status)
                    except Exception:
                        log.exception("trajectory listener %r failed", listener)

    # -- internals (lock held) --------------------------------------------------------------

    def _progress(self, start_tick: int, duration: float) -> tuple[int, float]:
        """(last tick sampled, elapsed / duration in 0..1) of a run that started then."""
        tick = max(self._last_tick, start_tick - 1)
        elapsed = (tick - start_tick + 1) * self.table.tick_dt
        if duration > 0:
            return tick, min(1.0, max(0.0, elapsed / duration))
        return tick, float(elapsed > 0)

    def _live(self, run: _Run, row: int | None = -1) -> TrajectoryStatus:
        """A running trajectory's status with progress and feedback as of the last tick.

        row: its row in the last feedback (None: none; -1: look it up)."""
        tick, progress = self._progress(run.start_tick, run.spec.duration)
        status = replace(run.status, tick=tick, progress=progress)
        fb_tick, ids, desired, actual = self._feedback
        if row == -1:
            rows = np.flatnonzero(ids == run.id)
            row = int(rows[0]) if rows.size else None
        if row is not None:
            i, j = row, run.spec.joints
            status = replace(
                status,
                feedback_tick=fb_tick,
                desired=desired[i, j].tolist(),
                actual=actual[i, j].tolist(),
                error=(actual[i, j] - desired[i, j]).tolist(),
            )
        return status

    def _succeed(self, st: Staging, worlds: np.ndarray, tick: int) -> None:
        if worlds.size == 0:
            return
        st.velocity[worlds] = 0.0  # the end is held without feed-forward
        st.dirty[worlds] = True
        self.loop.commands.wrote()
        self._finish(self.table.slots_of(worlds), TrajectoryState.SUCCEEDED, None, "", tick)

    def _abort(
        self, st: Staging | None, worlds: np.ndarray, reason: AbortReason, detail: str
    ) -> list[_Run]:
        slots = self.table.slots_of(worlds)
        if slots.size == 0:
            return []
        tick = None
        if st is not None:  # hold the last desired position without feed-forward
            w = self.table.worlds[slots]
            st.velocity[w] = 0.0
            st.dirty[w] = True
            self.loop.commands.wrote()
            tick = st.tick - 1  # the last tick it drove
        return self._finish(slots, TrajectoryState.ABORTED, reason, detail, tick)

    def _finish(
        self,
        slots: np.ndarray,
        state: TrajectoryState,
        reason: AbortReason | None,
        detail: str,
        tick: int | None,
    ) -> list[_Run]:
        done = []
        at = self.loop.tick if tick is None else tick
        rows = {traj_id: i for i, traj_id in enumerate(self._feedback[1].tolist())}
        for traj_id in self.table.ids[slots].tolist():
            run = self._runs[traj_id]
            live = self._live(run, rows.get(traj_id))
            run.status = replace(live, state=state, reason=reason, detail=detail, finished_tick=at)
            del self._runs[traj_id]
            self._finished[traj_id] = run
            done.append(run)
        keep = np.ones(len(self.table), dtype=bool)
        keep[slots] = False
        n = len(self._last)  # the slots the last sample covered: the first n (see observe)
        self._last, self._last_vel = self._last[keep[:n]], self._last_vel[keep[:n]]
        self.table.remove(slots)
        while len(self._finished) > _KEEP_FINISHED:
            old_id, old = self._finished.popitem(last=False)
            if self._by_world.get(old.world) == old_id:
                del self._by_world[old.world]
        self._done.extend(done)
        return done
