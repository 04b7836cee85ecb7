"""Losing and rebuilding a ShardedBatch's worker processes, the parent's side.

A worker that dies (killed, crashed) leaves its worlds paused, showing their last state, while
the other shards go on; a new worker is built in the background and swapped in at a tick
boundary, resuming from the last copy of that shard's state with the targets commanded since.
Kept apart from shards.py so that each module holds one job: shards.py splits and joins the
batch, this module keeps its workers alive.
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

from service.core.sim.types import BatchState, Snapshot
from service.engines.shard_arrays import ArrayReceiver
from service.engines.shard_worker import ready_reply, spawn
from service.engines.sharding import NOTHING, ShardPlan, StagedCommands, with_model

log = logging.getLogger("armfleet.shards")

# How often each worker shard's full state is copied into this process (after a step, on the
# sim thread: a host copy of that shard's arrays), so that a lost shard's worlds resume from at
# most this long ago instead of from home.
STATE_COPY_PERIOD = 2.0


class WorkerRecovery:
    """The health of a ShardedBatch's worker shards (numbered `_first`..shards-1) and their
    rebuilds. The tables below are set up by `_init_recovery`; `_health_lock` guards them."""

    shards: int
    _first: int
    _plan: ShardPlan
    _starts: np.ndarray
    _sizes: np.ndarray
    _kwargs: dict[str, Any]
    _conns: list[Connection]
    _procs: list[Any]
    _staged: StagedCommands
    _targets: np.ndarray
    _model_state: Any

    def _init_recovery(self) -> None:
        self._health_lock = threading.Lock()
        self._alive = [True] * self.shards
        self._problems: dict[int, str] = {}
        self._replacements: dict[int, tuple[Any, Connection]] = {}
        self._last_parts: dict[int, Snapshot] = {}
        self._fault_base = [np.zeros(int(n), dtype=np.int64) for n in self._sizes]
        self.restarts = 0
        self._copies: dict[int, tuple[float, BatchState]] = {}  # shard → (when, its state)
        # shard → its worker's shared block (a rebuilt worker's new block is opened by name)
        self._receivers = {i: ArrayReceiver() for i in self._workers()}

    def _conn(self, i: int) -> Connection:
        """Worker shard i's pipe."""
        return self._conns[i - self._first]

    def _recv_big(self, i: int) -> Any:
        """Worker shard i's reply of arrays (a snapshot, a state), through shared memory."""
        return self._receivers[i].recv(self._conn(i))

    def _workers(self) -> range:
        """The shard numbers held by worker processes."""
        return range(self._first, self.shards)

    def health(self) -> list[str]:
        """Problems now (empty when every shard runs); notices dead workers between ticks too.

        Cheap (a non-blocking wait per worker), so a watchdog may call it often from any thread.
        """
        for i in self._workers():
            if self._alive[i] and self._procs[i - self._first].exitcode is not None:
                self._lost(i, self._exit_reason(i))
        with self._health_lock:
            return [self._problems[i] for i in sorted(self._problems)]

    def _exit_reason(self, i: int) -> str:
        proc = self._procs[i - self._first]
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
                self._conn(i).send(("get_state", NOTHING))
                self._copies[i] = (now, self._recv_big(i))
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
            j = i - self._first
            old_conn, old_proc = self._conns[j], self._procs[j]
            with contextlib.suppress(OSError):
                old_conn.close()
            if old_proc.is_alive():
                old_proc.kill()
            self._conns[j], self._procs[j] = conn, proc
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

    def _stop_workers(self) -> None:
        """Stop every worker (and any replacement being built); kill those that linger."""
        spare: dict[int, tuple[Any, Connection]] = {}
        if hasattr(self, "_health_lock"):  # else closed while starting: no rebuilds yet
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
        for receiver in getattr(self, "_receivers", {}).values():
            receiver.close()
