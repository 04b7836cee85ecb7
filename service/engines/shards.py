"""ShardedBatch: one batch of worlds split across CPU cores, behind WorldBatch's interface.

Warp runs CPU kernels on one core, and two captured graphs replayed from two threads of one
process crash warp 1.19 (seen here: a segfault), so the second core is used by a worker
*process*. Shard 0 steps in the calling thread while shards 1.. step in their processes at the
same time; commands and snapshots cross a pipe as small numpy arrays. Worlds are independent, so
the result is bit-identical to one WorldBatch of the same size (tests/test_shards.py).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from service.core.batch import Batch, Renderable, Restorable, StateWrite, Supervised
from service.core.types import BatchState, Snapshot
from service.engines.cores import usable_cores
from service.engines.mirror import HostMirror
from service.engines.shard_worker import ready_reply, spawn
from service.engines.sharding import (
    NOTHING,
    ShardPlan,
    StagedCommands,
    join_snapshots,
    join_states,
    slice_state,
    stage_model,
    with_model,
)
from service.engines.warp import WorldBatch

log = logging.getLogger("armfleet.shards")

# The Batch facts that are the same for every shard (read from the local one).
_FACTS_OF_LOCAL = (
    "spec",
    "control_hz",
    "tick_dt",
    "substeps",
    "physics_dt",
    "device_name",
    "home_target",
    "compile_s",
    "capture_s",
    "capture_error",
)

# How often each worker shard's full state is copied into this process (after a step, on the
# sim thread: a host copy of that shard's arrays), so that a lost shard's worlds resume from at
# most this long ago instead of from home.
STATE_COPY_PERIOD = 2.0

# Below this many worlds per shard the pipe round trip (~0.1 ms) outweighs the second core.
MIN_WORLDS_PER_SHARD = 16


def auto_shards(nworld: int, device: str) -> int:
    """How many shards to use: one per core on the CPU when the batch is big enough."""
    if not device.startswith("cpu"):
        return 1
    return max(1, min(usable_cores(), nworld // MIN_WORLDS_PER_SHARD))


class ShardedBatch(HostMirror, Batch, Restorable, Supervised, Renderable):
    """N worlds as k contiguous shards; shard 0 local, the rest in worker processes."""

    def __init__(self, nworld: int, shards: int, **kwargs: Any) -> None:
        self._plan = ShardPlan(nworld, shards)
        self._starts, self._sizes = self._plan.starts, self._plan.sizes
        self._kwargs = kwargs
        self._conns: list[Connection] = []
        self._procs: list[Any] = []
        for size in self._sizes[1:]:
            proc, conn = spawn(int(size), kwargs)
            self._conns.append(conn)
            self._procs.append(proc)
        self._local = WorldBatch(int(self._sizes[0]), **kwargs)  # builds while workers build
        for conn in self._conns:
            reply = ready_reply(conn)
            if reply[0] == "error":
                self.close()
                raise RuntimeError(f"shard worker failed to start: {reply[1]}")
        self.nworld = nworld
        self.shards = shards
        self.robot = self._local.robot
        for name in _FACTS_OF_LOCAL:  # every shard is built alike: the local one speaks for all
            setattr(self, name, getattr(self._local, name))
        self._init_mirror(nworld)  # its tick and faults are the shards' own
        self._staged = StagedCommands(shards)
        # Losing a worker (killed, crashed): its worlds pause, showing their last state, while
        # the others go on; a new worker is built in the background and swapped in at a tick
        # boundary with the commanded targets of its worlds (their state starts from home).
        # Index i below is the shard number (1.. for workers); the lock guards these tables.
        self._health_lock = threading.Lock()
        self._alive = [True] * shards
        self._problems: dict[int, str] = {}
        self._replacements: dict[int, tuple[Any, Connection]] = {}
        self._last_parts: dict[int, Snapshot] = {}
        self._fault_base = [np.zeros(int(n), dtype=np.int64) for n in self._sizes]
        self.restarts = 0
        self._copies: dict[int, tuple[float, BatchState]] = {}  # shard → (when, its state)

    @property
    def captured(self) -> bool:
        return self._local.captured

    @property
    def tick(self) -> int:
        return self._local.tick

    def apply_targets(
        self, worlds: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None = None
    ) -> None:
        """The local shard gets its targets now, worker shards with their next step."""
        parts = self._plan.split(self._command(worlds, targets, velocities))
        if parts[0].size:
            vel = self._velocity[parts[0]]
            self._local.apply_targets(
                parts[0], self._targets[parts[0]], vel if velocities is not None else None
            )
        self._staged.targets_of(parts[1:], first=1)

    def reset(self, worlds: np.ndarray) -> None:
        worlds = np.asarray(worlds, dtype=np.int64)
        if worlds.size == 0:
            return
        self._home(worlds)
        parts = self._plan.split(worlds)
        self._local.reset(parts[0])
        self._staged.resets_of(parts[1:], first=1)

    def step(self, ticks: int = 1) -> np.ndarray:
        """Advance all live shards together; returns the (global) worlds reset for faults."""
        self._swap_in()
        sent = []
        for i, conn in enumerate(self._conns, start=1):
            if not self._alive[i]:
                continue  # its commands stay staged (and in _targets) for the new worker
            shipment = self._staged.ship(i, self._targets, self._velocity, self._starts[i])
            try:
                conn.send(("step", shipment, ticks))
            except OSError:
                self._lost(i, self._exit_reason(i))
                continue
            sent.append(i)
        faulted = [self._local.step(ticks)]
        for i in sent:
            try:
                faulted.append(self._conns[i - 1].recv() + self._starts[i])
            except (EOFError, OSError):
                self._lost(i, self._exit_reason(i))
        self._copy_states(sent)
        out = np.concatenate(faulted)
        self._home(out)
        return out

    def snapshot(self) -> Snapshot:
        self._swap_in()
        asked = []
        for i, conn in enumerate(self._conns, start=1):
            if self._alive[i]:
                try:
                    conn.send(("snapshot",))
                    asked.append(i)
                except OSError:
                    self._lost(i, self._exit_reason(i))
        parts = [self._local.snapshot()]
        for i in range(1, self.shards):
            part = None
            if i in asked:
                try:
                    part = self._conns[i - 1].recv()
                except (EOFError, OSError):
                    self._lost(i, self._exit_reason(i))
            if part is None:  # lost: its worlds show their last state until the rebuild
                part = self._last_parts[i]
            else:
                self._last_parts[i] = part
            parts.append(part)
        faults = np.concatenate(
            [p.faults + b for p, b in zip(parts, self._fault_base, strict=True)]
        )
        return dataclasses.replace(
            join_snapshots(parts, parts[0].tick, self._targets), faults=faults
        )

    def physics_shapes(self) -> dict[str, tuple[int, ...]]:
        return self._local.physics_shapes()

    def get_state(self) -> BatchState:
        """Every shard's state (staged commands applied first), joined in world order."""
        for i, conn in enumerate(self._conns, start=1):
            shipment = self._staged.ship(i, self._targets, self._velocity, self._starts[i])
            conn.send(("get_state", shipment))
        parts = [self._local.get_state()] + [conn.recv() for conn in self._conns]
        return join_states(parts, self._targets, self._model_state())

    def set_state(self, state: BatchState) -> None:
        """Split `state` over the shards; checked whole first so no shard is half-restored."""
        state.check_compatible(self.nworld, self.physics_shapes())
        model = self._check_model_state(state)
        self._copies.clear()  # copies of the replaced timeline must not come back after a loss
        for i in range(1, self.shards):
            self._staged.take(i)  # staged commands belonged to the state being replaced
        bounds = [*self._starts.tolist(), self.nworld]
        for i, conn in enumerate(self._conns, start=1):
            conn.send(("set_state", slice_state(state, bounds[i], bounds[i + 1])))
        self._local.set_state(slice_state(state, 0, bounds[1]))
        errors = [err for err in (conn.recv() for conn in self._conns) if err]
        if errors:  # cannot happen after the check above; say so loudly if it does
            raise RuntimeError(f"shard refused a checked state: {errors[0]}")
        self._restore_mirror(state, model)  # the shards took their slices of `model`

    def qpos(self) -> np.ndarray:
        return self._gather_qpos()[0]

    def qvel(self) -> np.ndarray:
        return self._gather_qpos()[1]

    def _gather_qpos(self) -> tuple[np.ndarray, np.ndarray]:
        for conn in self._conns:
            conn.send(("qpos",))
        parts = [(self._local.qpos(), self._local.qvel())] + [c.recv() for c in self._conns]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def write_state(self, write: StateWrite) -> None:
        """The local shard's now; a worker's with its next step, after its resets."""
        shard, local = self._plan.locate(write.world)
        if shard == 0:
            self._local.write_state(write.moved(local))
        else:
            self._staged.state(shard, write.moved(local))

    def render_state(self, worlds: np.ndarray) -> np.ndarray:
        """Renderable: the asked rows of every shard's qpos (one round trip to each worker)."""
        return self._gather_qpos()[0][np.asarray(worlds, dtype=np.int64)]

    def push_model(self, field: str, worlds: np.ndarray) -> None:
        """Staged for the shards holding the worlds, sent with their next step."""
        rows = self._model_rows(field, worlds)
        stage_model(self._plan, self._staged, field, rows, worlds, self._local)

    def write_qpos(self, world: int, qpos: np.ndarray) -> None:
        shard, local = self._plan.locate(world)
        if shard == 0:
            self._local.write_qpos(local, qpos)
        else:
            self._conns[shard - 1].send(("write_qpos", local, qpos))

    # -- losing and rebuilding workers ------------------------------------------------------

    def health(self) -> list[str]:
        """Problems now (empty when every shard runs); notices dead workers between ticks too.

        Cheap (a non-blocking wait per worker), so a watchdog may call it often from any thread.
        """
        for i, proc in enumerate(self._procs, start=1):
            if self._alive[i] and proc.exitcode is not None:
                self._lost(i, self._exit_reason(i))
        with self._health_lock:
            return [self._problems[i] for i in sorted(self._problems)]

    def _exit_reason(self, i: int) -> str:
        proc = self._procs[i - 1]
        proc.join(timeout=0.5)
        code = proc.exitcode
        if code is None:
            return "its pipe closed"
        return f"killed by signal {-code}" if code < 0 else f"exited with status {code}"

    def _lost(self, i: int, why: str) -> None:
        """Mark worker shard i dead and start building its replacement (once)."""
        with self._health_lock:
            if not self._alive[i]:
                return
            self._alive[i] = False
            lo, hi = int(self._starts[i]), int(self._starts[i] + self._sizes[i] - 1)
            self._problems[i] = f"shard {i} (worlds {lo}..{hi}) lost: {why}; rebuilding"
        log.error("shard %d (worlds %d..%d) lost: %s; rebuilding it", i, lo, hi, why)
        threading.Thread(
            target=self._rebuild, args=(i,), name=f"armfleet-rebuild-{i}", daemon=True
        ).start()

    def _rebuild(self, i: int) -> None:
        """Build a new worker for shard i (off the sim thread); it is swapped in by _swap_in."""
        for attempt in range(1, 4):
            proc, conn = spawn(int(self._sizes[i]), self._kwargs)
            reply = ready_reply(conn)
            if reply[0] == "ready":
                with self._health_lock:
                    self._replacements[i] = (proc, conn)
                return
            proc.kill()
            with self._health_lock:
                self._problems[i] = f"shard {i} rebuild attempt {attempt} failed: {reply[1]}"
            time.sleep(1.0)
        log.error("shard %d could not be rebuilt: %s", i, self._problems.get(i))

    def _copy_states(self, shards: list[int]) -> None:
        """Refresh the state copy of every live worker shard whose copy is older than the period."""
        now = time.monotonic()
        for i in shards:
            if not self._alive[i] or now - self._copies.get(i, (-1e9, None))[0] < STATE_COPY_PERIOD:
                continue
            try:
                self._conns[i - 1].send(("get_state", NOTHING))
                self._copies[i] = (now, self._conns[i - 1].recv())
            except (EOFError, OSError):
                self._lost(i, self._exit_reason(i))

    def _resume(self, i: int, conn: Connection) -> bool:
        """Put shard i's last state copy (with today's targets) into its new worker."""
        copy = self._copies.get(i)
        if copy is None:
            return False
        lo, hi = int(self._starts[i]), int(self._starts[i] + self._sizes[i])
        physics = with_model(copy[1].physics, self._model_state(), lo, hi)
        state = dataclasses.replace(copy[1], targets=self._targets[lo:hi].copy(), physics=physics)
        conn.send(("set_state", state))
        error = conn.recv()
        if error:
            log.error("shard %d: its state copy did not fit the new worker: %s", i, error)
            return False
        return True

    def _swap_in(self) -> None:
        """Put rebuilt workers in place at a tick boundary (sim thread), targets restored."""
        if not self._replacements:
            return
        with self._health_lock:
            ready, self._replacements = self._replacements, {}
        for i, (proc, conn) in ready.items():
            old_conn, old_proc = self._conns[i - 1], self._procs[i - 1]
            with contextlib.suppress(OSError):
                old_conn.close()
            if old_proc.is_alive():
                old_proc.kill()
            self._conns[i - 1], self._procs[i - 1] = conn, proc
            # Its worlds resume from the last state copy (else from home) with the targets
            # commanded since, and the loss counts as one fault for each of them.
            self._staged.take(i)  # staged resets are moot: the worlds restart anyway
            try:
                resumed = self._resume(i, conn)
            except (EOFError, OSError):
                resumed = False
            self._staged.targets(i, np.arange(int(self._sizes[i]), dtype=np.int64))
            last = self._last_parts.get(i)
            restarted_at = self._copies[i][1].faults if resumed else 0
            if last is not None:
                self._fault_base[i] = self._fault_base[i] + last.faults + 1 - restarted_at
            if not resumed:
                self._copies.pop(i, None)  # a copy of the old worker's counts no longer fits
            with self._health_lock:
                self._alive[i] = True
                self._problems.pop(i, None)
                self.restarts += 1
            how = "from its state copy" if resumed else "from home"
            log.warning("shard %d rebuilt and back in the batch; its worlds resume %s", i, how)

    def close(self) -> None:
        with self._health_lock:
            self._replacements, spare = {}, self._replacements
        for proc, conn in spare.values():
            with contextlib.suppress(OSError):
                conn.send(("stop",))
            proc.kill()
        for conn in self._conns:
            with contextlib.suppress(BrokenPipeError, OSError):
                conn.send(("stop",))
        for proc in self._procs:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.kill()
