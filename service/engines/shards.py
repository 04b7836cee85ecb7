"""ShardedBatch: one batch of worlds split across processes, behind WorldBatch's interface.

Warp runs CPU kernels on one core, and two captured graphs replayed from two threads of one
process crash warp 1.19 (seen here: a segfault), so the second core is used by a worker
*process*. Shard 0 steps in the calling thread while shards 1.. step in their processes at the
same time; commands and snapshots cross a pipe as small numpy arrays. Worlds are independent, so
the result is bit-identical to one WorldBatch of the same size (tests/test_shards.py).

With `local=False` every shard, shard 0 too, is a worker process: the engine then never runs in
the caller's process. That is how the cameras get a GPU of their own (`--camera-device`): Warp's
default device is one per process, so a renderer on cuda:1 and an engine on cuda:0 cannot share
one. Losing and rebuilding workers is `shard_recovery.py`.
"""

from __future__ import annotations

import dataclasses
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from service.core.sim.batch import Batch, Renderable, Restorable, StateWrite, Supervised
from service.core.sim.types import BatchState, Snapshot
from service.engines.cores import usable_cores
from service.engines.mirror import HostMirror
from service.engines.shard_recovery import WorkerRecovery
from service.engines.shard_worker import FACTS, ready_reply, spawn
from service.engines.sharding import (
    ShardPlan,
    StagedCommands,
    join_snapshots,
    join_states,
    slice_state,
    stage_model,
)
from service.engines.warp import WorldBatch

# Below this many worlds per shard the pipe round trip (~0.1 ms) outweighs the second core.
MIN_WORLDS_PER_SHARD = 16


def auto_shards(nworld: int, device: str) -> int:
    """How many shards to use: one per core on the CPU when the batch is big enough."""
    if not device.startswith("cpu"):
        return 1
    return max(1, min(usable_cores(), nworld // MIN_WORLDS_PER_SHARD))


class ShardedBatch(HostMirror, WorkerRecovery, Batch, Restorable, Supervised, Renderable):
    """N worlds as k contiguous shards; shard 0 local (unless `local=False`), the rest (or all)
    in worker processes."""

    def __init__(self, nworld: int, shards: int, local: bool = True, **kwargs: Any) -> None:
        self._plan = ShardPlan(nworld, shards)
        self._starts, self._sizes = self._plan.starts, self._plan.sizes
        self._kwargs = kwargs
        self._first = 1 if local else 0  # the first shard held by a worker process
        self._conns: list[Connection] = []
        self._procs: list[Any] = []
        for size in self._sizes[self._first :]:
            proc, conn = spawn(int(size), kwargs)
            self._conns.append(conn)
            self._procs.append(proc)
        # builds while the workers build
        self._local = WorldBatch(int(self._sizes[0]), **kwargs) if local else None
        replies = [ready_reply(conn) for conn in self._conns]
        for reply in replies:
            if reply[0] == "error":
                self.close()
                raise RuntimeError(f"shard worker failed to start: {reply[1]}")
        self.nworld = nworld
        self.shards = shards
        # every shard is built alike: the local one, else the first worker, speaks for all
        local_facts = {name: getattr(self._local, name) for name in FACTS} if local else {}
        facts = local_facts or replies[0][-1]
        for name in FACTS:
            setattr(self, name, facts[name])
        # what a local shard answers itself (the properties below), a worker said when ready
        self._captured = bool(facts.get("captured", False))
        self._shapes = facts.get("physics_shapes", {})
        self._init_mirror(nworld)  # its tick and faults are the shards' own
        self._staged = StagedCommands(shards)
        # Losing a worker (killed, crashed): its worlds pause, showing their last state, while
        # the others go on; a new worker is built in the background and swapped in at a tick
        # boundary with the commanded targets of its worlds (shard_recovery.py).
        self._init_recovery()

    @property
    def captured(self) -> bool:
        return self._local.captured if self._local is not None else self._captured

    @property
    def tick(self) -> int:
        return self._local.tick if self._local is not None else self._tick

    def apply_targets(
        self, worlds: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None = None
    ) -> None:
        """The local shard gets its targets now, worker shards with their next step."""
        parts = self._plan.split(self._command(worlds, targets, velocities))
        if self._local is not None and parts[0].size:
            vel = self._velocity[parts[0]]
            self._local.apply_targets(
                parts[0], self._targets[parts[0]], vel if velocities is not None else None
            )
        self._staged.targets_of(parts[self._first :], first=self._first)

    def reset(self, worlds: np.ndarray) -> None:
        worlds = np.asarray(worlds, dtype=np.int64)
        if worlds.size == 0:
            return
        self._home(worlds)
        parts = self._plan.split(worlds)
        if self._local is not None:
            self._local.reset(parts[0])
        self._staged.resets_of(parts[self._first :], first=self._first)

    def step(self, ticks: int = 1) -> np.ndarray:
        """Advance all live shards together; returns the (global) worlds reset for faults."""
        self._swap_in()
        sent = []
        for i in self._workers():
            if not self._alive[i]:
                continue  # its commands stay staged (and in _targets) for the new worker
            shipment = self._staged.ship(i, self._targets, self._velocity, self._starts[i])
            try:
                self._conn(i).send(("step", shipment, ticks))
            except OSError:
                self._lost(i, self._exit_reason(i))
                continue
            sent.append(i)
        faulted = [self._local.step(ticks)] if self._local is not None else []
        for i in sent:
            try:
                faulted.append(self._conn(i).recv() + self._starts[i])
            except (EOFError, OSError):
                self._lost(i, self._exit_reason(i))
        if self._local is None and sent:
            self._tick += ticks  # every shard a worker: counted here, while any of them steps
        self._copy_states(sent)
        out = np.concatenate(faulted) if faulted else np.zeros(0, dtype=np.int64)
        self._home(out)
        return out

    def snapshot(self) -> Snapshot:
        self._swap_in()
        asked = []
        for i in self._workers():
            if self._alive[i]:
                try:
                    self._conn(i).send(("snapshot",))
                    asked.append(i)
                except OSError:
                    self._lost(i, self._exit_reason(i))
        parts = [self._local.snapshot()] if self._local is not None else []
        for i in self._workers():
            part = None
            if i in asked:
                try:
                    part = self._recv_big(i)
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
        return dataclasses.replace(join_snapshots(parts, self.tick, self._targets), faults=faults)

    def physics_shapes(self) -> dict[str, tuple[int, ...]]:
        return self._local.physics_shapes() if self._local is not None else dict(self._shapes)

    def get_state(self) -> BatchState:
        """Every shard's state (staged commands applied first), joined in world order."""
        for i in self._workers():
            shipment = self._staged.ship(i, self._targets, self._velocity, self._starts[i])
            self._conn(i).send(("get_state", shipment))
        parts = [self._local.get_state()] if self._local is not None else []
        parts += [self._recv_big(i) for i in self._workers()]
        state = join_states(parts, self._targets, self._model_state())
        return dataclasses.replace(state, tick=self.tick)

    def set_state(self, state: BatchState) -> None:
        """Split `state` over the shards; checked whole first so no shard is half-restored."""
        state.check_compatible(self.nworld, self.physics_shapes())
        model = self._check_model_state(state)
        self._copies.clear()  # copies of the replaced timeline must not come back after a loss
        for i in self._workers():
            self._staged.take(i)  # staged commands belonged to the state being replaced
        bounds = [*self._starts.tolist(), self.nworld]
        for i in self._workers():
            self._conn(i).send(("set_state", slice_state(state, bounds[i], bounds[i + 1])))
        if self._local is not None:
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
        parts = [(self._local.qpos(), self._local.qvel())] if self._local is not None else []
        parts += [c.recv() for c in self._conns]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def write_state(self, write: StateWrite) -> None:
        """The local shard's now; a worker's with its next step, after its resets."""
        shard, local = self._plan.locate(write.world)
        if shard == 0 and self._local is not None:
            self._local.write_state(write.moved(local))
        else:
            self._staged.state(shard, write.moved(local))

    def render_state(self, worlds: np.ndarray) -> np.ndarray:
        """Renderable: the asked worlds' qpos rows, in the order asked; each shard holding some
        sends only those (16,384 worlds' rows of a GPU engine cross in about a millisecond)."""
        ids = np.asarray(worlds, dtype=np.int64)
        shard_of = np.searchsorted(self._starts, ids, side="right") - 1
        asked = [(i, shard_of == i) for i in range(self.shards)]
        asked = [(i, m) for i, m in asked if m.any()]
        for i, mask in asked:
            if i >= self._first:
                self._conn(i).send(("render_state", ids[mask] - self._starts[i]))
        out = np.empty((len(ids), self.robot.mjm.nq), dtype=np.float32)  # warp's qpos type
        for i, mask in asked:
            if i < self._first:  # the local shard, whose ids are the global ones
                out[mask] = self._local.render_state(ids[mask])
            else:
                out[mask] = self._conn(i).recv()
        return out

    def push_model(self, field: str, worlds: np.ndarray) -> None:
        """Staged for the shards holding the worlds, sent with their next step."""
        rows = self._model_rows(field, worlds)
        stage_model(self._plan, self._staged, field, rows, worlds, self._local)

    def write_qpos(self, world: int, qpos: np.ndarray) -> None:
        shard, local = self._plan.locate(world)
        if shard == 0 and self._local is not None:
            self._local.write_qpos(local, qpos)
        else:
            # what is staged for it (a reset, say) goes first, as it would in this process
            shipment = self._staged.ship(shard, self._targets, self._velocity, self._starts[shard])
            self._conn(shard).send(("write_qpos", shipment, local, qpos))

    def stepping_ids(self) -> tuple[int, ...]:
        """The worker processes stepping shards now (SteppedBeside), rebuilt ones once swapped
        in; a process's first thread, whose id is its pid, is the one that steps."""
        return tuple(p.pid for p in self._procs if p.pid is not None)

    def close(self) -> None:
        self._stop_workers()
