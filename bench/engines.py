"""Sections 10, 12 and 13: the two engines side by side (section 11: capacity.py).

10. ``engines``: native MuJoCo vs MuJoCo Warp vs raw ``mujoco.rollout`` on every core, at the
    same sizes in one run: each engine alone in this process, then ``armfleet serve --mode fast
    --engine mujoco|warp`` with every world streamed at 30 Hz (JSON, one client), in rounds
    with a raw rollout block run while the service is paused. Every figure is the best of its
    rounds (all samples are in the JSON): on a shared machine that compares the code.
11. ``capacity_engines``: moved to bench/capacity.py.
12. ``physics_step``: the gain of the larger physics step: each engine alone at the step used
    before issue 13 (2.083 ms, 8 substeps) and at today's default, ticks/s (best block) and the
    worlds that rate would hold at 60 Hz.
13. ``kernels``: where MuJoCo Warp's CPU tick goes: the uncaptured tick with every ``wp.launch``
    timed (CPU launches are synchronous), each kernel's median over the ticks, the top kernels
    at 64 and 1024 worlds.

Standalone: ``python -m bench.engines --section 10 --worlds 1024``.
"""

from __future__ import annotations

import asyncio
import collections
import time
from typing import Any

from bench import common
from bench.registry import Context, Result, section
from bench.service_bench import _measure_fast

ENGINE_NAMES = ("mujoco", "warp")


def _engine_rate(
    engine: str, nworld: int, physics_dt: float, block_s: float, rounds: int = 5
) -> dict[str, Any]:
    """One engine alone in this process: ticks/s of `step(1)`, the best of `rounds` blocks.

    The best block is the one least disturbed by other processes: on a shared machine the mean
    says more about the neighbours than about the engine.
    """
    if engine == "mujoco":
        from service.engines.native import NativeBatch

        batch: Any = NativeBatch(nworld, physics_dt=physics_dt)
    else:
        from service.engines.shards import ShardedBatch, auto_shards
        from service.engines.warp import WorldBatch

        shards = auto_shards(nworld, "cpu")
        batch = (
            ShardedBatch(nworld, shards, physics_dt=physics_dt)
            if shards > 1
            else WorldBatch(nworld, physics_dt=physics_dt)
        )
    try:
        batch.step(2)
        blocks = []
        for _ in range(rounds):
            timing = common.time_calls(lambda: batch.step(1), block_s)
            blocks.append(timing.reps / timing.elapsed)
        ticks_per_s = max(blocks)
        return {
            "nworld": nworld,
            "substeps": batch.substeps,
            "physics_dt": batch.physics_dt,
            "shards": batch.shards,
            "ticks_per_s": ticks_per_s,
            "ticks_per_s_blocks": blocks,
            "world_steps_per_s": ticks_per_s * nworld * batch.substeps,
            "realtime_worlds_60hz": nworld * ticks_per_s / common.CONTROL_HZ,
        }
    finally:
        batch.close()


class _Rollout:
    """Raw native MuJoCo: `mujoco.rollout.Rollout` on `nthread` threads, chained calls."""

    def __init__(self, nworld: int, nthread: int, physics_dt: float, solver: Any = None) -> None:
        """`solver`: a mujoco.mjtSolver; None: the native engine's (physics.ENGINE_SOLVER)."""
        import math

        import mujoco
        import numpy as np
        from mujoco import rollout

        from service.core.sim.physics import ENGINE_SOLVER, configure
        from service.core.sim.robot import load_robot

        robot = load_robot()
        self.mjm = mjm = robot.mjm
        configure(mjm, physics_dt, ENGINE_SOLVER["mujoco"] if solver is None else solver)
        data = mujoco.MjData(mjm)
        mujoco.mj_resetDataKeyframe(mjm, data, robot.home_key)
        mujoco.mj_forward(mjm, data)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state0 = np.empty(mujoco.mj_stateSize(mjm, spec))
        mujoco.mj_getState(mjm, data, state0, spec)
        # ~50 ms a call at ~1e5 steps/s per thread, as section 1 does.
        self.nstep = int(min(200, max(1, math.ceil(0.05 * 1e5 * nthread / nworld))))
        self.nworld = nworld
        self.initial = np.tile(state0, (nworld, 1))
        self.control = np.tile(data.ctrl.copy(), (nworld, self.nstep, 1))
        self.states = np.empty((nworld, self.nstep, state0.size))
        self.datas = [mujoco.MjData(mjm) for _ in range(nthread)]
        self.pool = rollout.Rollout(nthread=nthread)

    def block(self, seconds: float) -> float:
        """World-steps/s over one block of about `seconds`."""

        def call() -> None:
            out = self.states
            self.pool.rollout(
                self.mjm, self.datas, self.initial, self.control, nstep=self.nstep, state=out
            )
            self.initial[:] = self.states[:, -1, :]

        timing = common.time_calls(call, seconds)
        return timing.reps * self.nstep * self.nworld / timing.elapsed

    def close(self) -> None:
        self.pool.close()


async def _served_vs_rollout(
    server: common.Served,
    rollout: _Rollout,
    rounds: int,
    window: float,
    block_s: float,
    fmt: str = "json",
) -> dict[str, Any]:
    """Rounds of: service paused → a rollout block → service in fast mode for `window`.

    The service streams every world at 30 Hz (`fmt` frames, one client) throughout; pausing it while
    rollout runs keeps the two from sharing the cores. Best of the rounds for each.
    """
    import httpx

    from bench.service_bench import FrameCounter, _info

    counter = FrameCounter()
    reader = asyncio.create_task(counter.run(f"{server.ws_url}/v1/ws?rate=30&format={fmt}"))
    served: list[float] = []
    raw: list[float] = []
    try:
        async with httpx.AsyncClient(base_url=server.url, timeout=60) as client:
            await asyncio.sleep(1.0)
            for _ in range(rounds):
                (await client.post("/v1/sim/pause")).raise_for_status()
                raw.append(await asyncio.to_thread(rollout.block, block_s))
                (await client.post("/v1/sim/mode", json={"mode": "fast"})).raise_for_status()
                await asyncio.sleep(0.5)
                counter.reset()
                t0, info0 = await _info(client, server.url)
                await asyncio.sleep(window)
                t1, info1 = await _info(client, server.url)
                steps = common.world_steps(
                    info1["tick"] - info0["tick"], server.nworld, info1["substeps"]
                )
                served.append(steps / (t1 - t0))
    finally:
        reader.cancel()
        await asyncio.gather(reader, return_exceptions=True)
    return {
        "world_steps_per_s": max(served),
        "world_steps_per_s_windows": served,
        "rollout_world_steps_per_s": max(raw),
        "rollout_blocks": raw,
        "frames_last_window": counter.frames,
        "stream_error": counter.error,
    }


def _serve_fast(ctx: Context, engine: str, nworld: int, duration: float, warmup: float) -> dict:
    with ctx.serve(nworld, "fast", env={"ARMFLEET_ENGINE": engine}) as server:
        return asyncio.run(_measure_fast(server, duration, warmup, "json"))


@section(10, "engines", "Native MuJoCo vs MuJoCo Warp vs raw rollout, world-steps/s, one run")
def engines(ctx: Context) -> Result:
    """Each engine served in fast mode, rollout blocks between its windows; engines alone too.

    Every figure is the best of its rounds (see `_engine_rate`): on a shared machine that is
    the least disturbed sample of each, so the ratios compare the code, not the neighbours.
    """
    sizes = ctx.sizes((64, 256, 1024), (1024,))
    rounds, window, block_s = ctx.pick((5, 2.0, 1.0), (2, 1.0, 0.5))
    cores = common.usable_cores()
    _, dt = _default_step()

    def one(n: int) -> dict[str, Any]:
        out: dict[str, Any] = {"nworld": n, "threads": cores}
        for engine in ENGINE_NAMES:
            out[f"{engine}_alone"] = _engine_rate(engine, n, dt, block_s, rounds)
        rollout = _Rollout(n, cores, dt)
        try:
            for engine in ENGINE_NAMES:
                with ctx.serve(n, "fast", env={"ARMFLEET_ENGINE": engine}) as server:
                    out[f"{engine}_service"] = asyncio.run(
                        _served_vs_rollout(server, rollout, rounds, window, block_s)
                    )
                    if (
                        engine == "mujoco"
                    ):  # the same server, binary frames (service/core/streams/wire.py)
                        out["mujoco_service_binary"] = asyncio.run(
                            _served_vs_rollout(server, rollout, rounds, window, block_s, "binary")
                        )
        finally:
            rollout.close()
        out["rollout"] = rollout_best = max(
            out[k]["rollout_world_steps_per_s"]
            for k in ("mujoco_service", "mujoco_service_binary", "warp_service")
        )
        out["mujoco_service_binary_vs_rollout"] = (
            out["mujoco_service_binary"]["world_steps_per_s"] / rollout_best
        )
        for engine in ENGINE_NAMES:
            served = out[f"{engine}_service"]["world_steps_per_s"]
            out[f"{engine}_service_vs_rollout"] = served / rollout_best
            out[f"{engine}_alone_vs_rollout"] = (
                out[f"{engine}_alone"]["world_steps_per_s"] / rollout_best
            )
        return out

    results, errors = ctx.each(
        sizes,
        one,
        lambda r: (
            f"rollout {r['rollout']:,.0f}, native service {r['mujoco_service_vs_rollout']:.2f}x, "
            f"warp service {r['warp_service_vs_rollout']:.2f}x"
        ),
    )
    rows = [
        {
            "worlds": int(n),
            f"rollout {cores}t": r["rollout"],
            "native alone": r["mujoco_alone"]["world_steps_per_s"],
            "warp alone": r["warp_alone"]["world_steps_per_s"],
            "native served": r["mujoco_service"]["world_steps_per_s"],
            "warp served": r["warp_service"]["world_steps_per_s"],
            "native svc/rollout": r["mujoco_service_vs_rollout"],
            "native binary svc/rollout": r["mujoco_service_binary_vs_rollout"],
            "warp svc/rollout": r["warp_service_vs_rollout"],
        }
        for n, r in results.items()
    ]
    data = {
        "physics_dt": dt,
        "stream": "/v1/ws?rate=30&format=json (all worlds, one client)",
        "rollout": "mujoco.rollout.Rollout(nthread=usable cores), blocks while the service is "
        "paused, best block",
        "rounds": rounds,
        "window_s": window,
        "block_s": block_s,
        "results": results,
        "errors": errors,
    }
    notes = [
        "best of each figure's rounds; target: native served >= 0.9x raw rollout at 1024 worlds"
    ]
    return Result(rows, data, notes)


def _default_step() -> tuple[int, float]:
    from service.core.sim.physics import tick_timing

    return tick_timing(common.CONTROL_HZ, common.PHYSICS_DT)


@section(12, "physics_step", "Physics step: before (2.083 ms) vs today's default, engine alone")
def physics_step(ctx: Context) -> Result:
    """Each engine alone at the old and the new step: ticks/s and 60 Hz worlds that rate holds."""
    from service.core.sim.physics import tick_timing

    sizes = ctx.sizes((64, 1024), (64,))
    block_s, rounds = ctx.pick((1.0, 5), (0.3, 2))
    steps = {
        "old": tick_timing(common.CONTROL_HZ, common.OLD_PHYSICS_DT),
        "new": _default_step(),
    }

    def one(n: int) -> dict[str, Any]:
        out: dict[str, Any] = {"nworld": n}
        for engine in ENGINE_NAMES:
            for label, (_, dt) in steps.items():
                out[f"{engine}_{label}"] = _engine_rate(engine, n, dt, block_s, rounds)
            out[f"{engine}_gain"] = (
                out[f"{engine}_new"]["ticks_per_s"] / out[f"{engine}_old"]["ticks_per_s"]
            )
        return out

    results, errors = ctx.each(
        sizes, one, lambda r: f"gain warp {r['warp_gain']:.2f}x, native {r['mujoco_gain']:.2f}x"
    )
    rows = []
    for n, r in results.items():
        for engine in ENGINE_NAMES:
            old, new = r[f"{engine}_old"], r[f"{engine}_new"]
            rows.append(
                {
                    "worlds": int(n),
                    "engine": engine,
                    f"ticks/s at {old['physics_dt'] * 1e3:.3f} ms": old["ticks_per_s"],
                    f"ticks/s at {new['physics_dt'] * 1e3:.3f} ms": new["ticks_per_s"],
                    "gain": r[f"{engine}_gain"],
                    "60 Hz worlds before": old["realtime_worlds_60hz"],
                    "60 Hz worlds now": new["realtime_worlds_60hz"],
                }
            )
    data = {
        "steps": {k: {"substeps": s, "physics_dt": dt} for k, (s, dt) in steps.items()},
        "results": results,
        "errors": errors,
    }
    note = "60 Hz worlds = worlds x ticks/s / 60: the engine alone, before any service overhead"
    return Result(rows, data, [note])


def _kernel_profile(nworld: int, ticks: int) -> dict[str, Any]:
    """Time every wp.launch of `ticks` uncaptured ticks (CPU launches run to completion).

    Each kernel's figure is its median over the ticks, so that a tick in which another process
    took the core does not count (the machine may be shared).
    """
    import statistics

    import warp as wp

    from service.engines.warp import WorldBatch

    batch = WorldBatch(nworld, capture=False)
    batch.step(2)
    per_tick: list[dict[str, float]] = []
    calls: collections.Counter[str] = collections.Counter()
    launch = wp.launch

    def timed(kernel: Any, *args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return launch(kernel, *args, **kwargs)
        finally:
            name = getattr(kernel, "key", str(kernel)).replace("__locals__", ".")
            per_tick[-1][name] = per_tick[-1].get(name, 0.0) + time.perf_counter() - t0
            calls[name] += 1

    walls = []
    wp.launch = timed  # mujoco_warp launches through the `wp` module's attribute
    try:
        for _ in range(ticks):
            per_tick.append({})
            t0 = time.perf_counter()
            batch.step(1)
            walls.append(time.perf_counter() - t0)
    finally:
        wp.launch = launch
    names = set().union(*per_tick)
    spent = {k: statistics.median(t.get(k, 0.0) for t in per_tick) for k in names}
    total = sum(spent.values())
    top = sorted(spent.items(), key=lambda kv: -kv[1])
    return {
        "nworld": nworld,
        "ticks": ticks,
        "ms_per_tick_uncaptured": statistics.median(walls) * 1e3,
        "ms_per_tick_in_launches": total * 1e3,
        "launches_per_tick": sum(calls.values()) / ticks,
        "kernels": [
            {
                "kernel": k,
                "ms_per_tick": v * 1e3,
                "share": v / total,
                "launches_per_tick": calls[k] / ticks,
            }
            for k, v in top
        ],
    }


@section(13, "kernels", "MuJoCo Warp CPU tick: top kernels (uncaptured, each launch timed)")
def kernels(ctx: Context) -> Result:
    """The uncaptured warp tick at 64 and 1024 worlds, every launch timed; the top ten each."""
    sizes = ctx.sizes((64, 1024), (64,))
    ticks = ctx.pick(15, 5)
    results, errors = ctx.each(
        sizes,
        lambda n: _kernel_profile(n, ticks),
        lambda r: f"{r['ms_per_tick_uncaptured']:.1f} ms/tick, top {r['kernels'][0]['kernel']}",
    )
    rows = [
        {
            "worlds": int(n),
            "kernel": k["kernel"][:48],
            "ms/tick": k["ms_per_tick"],
            "share": k["share"],
            "launches/tick": k["launches_per_tick"],
        }
        for n, r in results.items()
        for k in r["kernels"][:10]
    ]
    note = (
        "launch overhead (~tens of µs each, ~190 launches a tick) is inside each figure; the "
        "service replays a captured tick, which removes it"
    )
    return Result(rows, {"results": results, "errors": errors}, [note])


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
