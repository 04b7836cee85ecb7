"""A process shard's worker: the process that holds one block of worlds for ShardedBatch.

It builds a WorldBatch of its worlds, says ready (or why not), then serves the parent's
requests over a pipe until told to stop or the parent goes. shards.py is the parent's side.
"""

from __future__ import annotations

import multiprocessing as mp
from multiprocessing.connection import Connection
from typing import Any

from service.core.process.lean_spawn import main_not_reimported
from service.core.process.stopping import start_worker
from service.engines.shard_arrays import ArraySender
from service.engines.sharding import apply_and_step
from service.engines.warp import WorldBatch

# The Batch facts that are the same for every shard: the parent reads them from its local
# shard, or (every shard a worker) from the first worker's ready message.
FACTS = (
    "robot",
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


def worker(conn: Connection, nworld: int, kwargs: dict[str, Any]) -> None:
    """A shard's process: build the batch, then serve step/snapshot/reset/targets requests."""
    try:
        batch = WorldBatch(nworld, **kwargs)
    except Exception as exc:  # report instead of leaving the parent waiting
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    facts = {name: getattr(batch, name) for name in FACTS}
    facts |= {"captured": batch.captured, "physics_shapes": batch.physics_shapes()}
    conn.send(("ready", batch.compile_s, batch.capture_s, batch.capture_error, facts))
    big = ArraySender()  # snapshots and states go through shared memory (shard_arrays.py)
    try:
        _serve(conn, batch, big)
    finally:
        big.close()


def _serve(conn: Connection, batch: WorldBatch, big: ArraySender) -> None:
    """Answer the parent's requests until it says stop or goes."""
    while True:
        try:
            op, *args = conn.recv()
        except EOFError:  # parent gone
            return
        if op == "step":
            conn.send(apply_and_step(batch, *args))
        elif op == "get_state":
            args[0].apply(batch)  # staged commands are part of the state
            big.send(conn, batch.get_state())
        elif op == "set_state":
            try:
                batch.set_state(args[0])
                conn.send(None)
            except ValueError as exc:
                conn.send(str(exc))
        elif op == "snapshot":
            big.send(conn, batch.snapshot())
        elif op == "write_qpos":
            args[0].apply(batch)  # staged commands come first
            batch.write_qpos(*args[1:])
        elif op == "render_state":
            conn.send(batch.render_state(args[0]))
        elif op == "qpos":
            conn.send((batch.qpos(), batch.qvel()))
        elif op == "stop":
            return


def spawn(nworld: int, kwargs: dict[str, Any]) -> tuple[Any, Connection]:
    """Start a worker process building `nworld` worlds; its first message says ready or not."""
    ctx = mp.get_context("spawn")  # fork would copy a live warp runtime
    parent, child = ctx.Pipe()
    with main_not_reimported():  # not service/cli.py again (lean_spawn.py)
        proc = start_worker(ctx, worker, (child, nworld, kwargs))  # stopping: core/stopping
    child.close()  # so that a dead worker shows up as EOFError, not a hang
    return proc, parent


def ready_reply(conn: Connection) -> tuple[Any, ...]:
    try:
        return conn.recv()
    except (EOFError, OSError):
        return ("error", "worker exited while building its shard")
