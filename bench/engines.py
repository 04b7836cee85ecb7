"""Sections 10 and 12: the two engines side by side (11: capacity.py; 13: kernels.py).

10. ``engines``: native MuJoCo vs MuJoCo Warp vs raw ``mujoco.rollout`` on every core, at the
    same sizes in one run: each engine alone in this process, then ``armfleet serve --mode fast
    --engine mujoco|warp`` with every world streamed at 30 Hz (JSON, one client), in rounds
    with a raw rollout block run while the service is paused. Every figure is the best of its
    rounds (all samples are in the JSON): on a shared machine that compares the code.
11. ``capacity_engines``: moved to bench/capacity.py.
12. ``physics_step``: the gain of the larger physics step: each engine alone at the step used
    before issue 13 (2.083 ms, 8 substeps) and at today's default, ticks/s (best block) and the
    worlds that rate would hold at 60 Hz.
13. ``kernels``: moved to bench/kernels.py.

Standalone: ``python -m bench.engines --section 10 --worlds 1024``.
"""

from __future__ import annotations

import asyncio
from typing import Any

from bench import common
from bench.baselines import Rollout, physics_dt
from bench.registry import Context, Result, section
from bench.service_probe import FrameCounter, timed_info

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


async def _served_vs_rollout(
    server: common.Served,
    rollout: Rollout,
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
                t0, info0 = await timed_info(client, server.url)
                await asyncio.sleep(window)
                t1, info1 = await timed_info(client, server.url)
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


@section(10, "engines")
def engines(ctx: Context) -> Result:
    """Native MuJoCo vs MuJoCo Warp vs raw rollout, world-steps/s, one run

    Each engine served in fast mode, rollout blocks between its windows; engines alone too.

    Every figure is the best of its rounds (see `_engine_rate`): on a shared machine that is
    the least disturbed sample of each, so the ratios compare the code, not the neighbours.
    """
    sizes = ctx.sizes((64, 256, 1024), (1024,))
    rounds, window, block_s = ctx.pick((5, 2.0, 1.0), (2, 1.0, 0.5))
    cores = common.usable_cores()
    _, dt = physics_dt()

    def one(n: int) -> dict[str, Any]:
        out: dict[str, Any] = {"nworld": n, "threads": cores}
        for engine in ENGINE_NAMES:
            out[f"{engine}_alone"] = _engine_rate(engine, n, dt, block_s, rounds)
        rollout = Rollout(n, cores, dt)
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


@section(12, "physics_step")
def physics_step(ctx: Context) -> Result:
    """Physics step: before (2.083 ms) vs today's default, engine alone

    Each engine alone at the old and the new step: ticks/s and 60 Hz worlds that rate holds."""
    from service.core.sim.physics import tick_timing

    sizes = ctx.sizes((64, 1024), (64,))
    block_s, rounds = ctx.pick((1.0, 5), (0.3, 2))
    steps = {
        "old": tick_timing(common.CONTROL_HZ, common.OLD_PHYSICS_DT),
        "new": physics_dt(),
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


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
