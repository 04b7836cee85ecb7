"""Sections 10-13: the two engines side by side (issue 13).

10. ``engines``: native MuJoCo vs MuJoCo Warp vs raw ``mujoco.rollout`` on every core, at the
    same sizes in one run: each engine alone in this process, then ``armfleet serve --mode fast
    --engine mujoco|warp`` with every world streamed at 30 Hz (JSON, one client). Raw rollout is
    measured before and after the services and averaged, so that drift on a shared machine
    shows (both figures are in the JSON).
11. ``capacity_engines``: the most worlds each engine holds in real time (RTF >= 0.99 over the
    window) at 60 Hz with ONE 30 Hz subscriber of every world; doubling, then bisection.
12. ``physics_step``: the gain of the larger physics step: each engine alone at the step used
    before issue 13 (2.083 ms, 8 substeps) and at today's default, ticks/s and the worlds that
    rate would hold at 60 Hz.
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
from bench.service_bench import RTF_GOAL, _measure_fast, _measure_realtime, capacity_search

ENGINE_NAMES = ("mujoco", "warp")


def _engine_rate(engine: str, nworld: int, physics_dt: float, min_time: float) -> dict[str, Any]:
    """One engine alone in this process: ticks/s and world-steps/s of `step(1)`."""
    if engine == "mujoco":
        from service.native import NativeBatch

        batch: Any = NativeBatch(nworld, physics_dt=physics_dt)
    else:
        from service.engine import WorldBatch
        from service.shards import ShardedBatch, auto_shards

        shards = auto_shards(nworld, "cpu")
        batch = (
            ShardedBatch(nworld, shards, physics_dt=physics_dt)
            if shards > 1
            else WorldBatch(nworld, physics_dt=physics_dt)
        )
    try:
        timing = common.time_calls(lambda: batch.step(1), min_time, warmup_time=0.3)
        ticks_per_s = timing.reps / timing.elapsed
        return {
            "nworld": nworld,
            "substeps": batch.substeps,
            "physics_dt": batch.physics_dt,
            "shards": batch.shards,
            "ticks_per_s": ticks_per_s,
            "world_steps_per_s": ticks_per_s * nworld * batch.substeps,
            "realtime_worlds_60hz": nworld * ticks_per_s / common.CONTROL_HZ,
        }
    finally:
        batch.close()


def _serve_fast(ctx: Context, engine: str, nworld: int, duration: float, warmup: float) -> dict:
    with ctx.serve(nworld, "fast", env={"ARMFLEET_ENGINE": engine}) as server:
        return asyncio.run(_measure_fast(server, duration, warmup, "json"))


@section(10, "engines", "Native MuJoCo vs MuJoCo Warp vs raw rollout, world-steps/s, one run")
def engines(ctx: Context) -> Result:
    """Raw rollout, each engine alone, each engine served in fast mode: same sizes, one run."""
    from bench.throughput import bench_rollout

    sizes = ctx.sizes((64, 256, 1024), (1024,))
    min_time, duration, warmup = ctx.pick((2.0, 8.0, 2.0), (0.8, 3.0, 1.0))
    cores = common.usable_cores()
    _, dt = _default_step()

    def one(n: int) -> dict[str, Any]:
        out: dict[str, Any] = {"nworld": n, "threads": cores}
        before = bench_rollout(n, cores, min_time, 0.3)["world_steps_per_s"]
        for engine in ENGINE_NAMES:
            out[f"{engine}_alone"] = _engine_rate(engine, n, dt, min_time)
        for engine in ENGINE_NAMES:
            out[f"{engine}_service"] = _serve_fast(ctx, engine, n, duration, warmup)
        after = bench_rollout(n, cores, min_time, 0.3)["world_steps_per_s"]
        out["rollout_before"], out["rollout_after"] = before, after
        out["rollout"] = rollout = (before + after) / 2
        for engine in ENGINE_NAMES:
            served = out[f"{engine}_service"]["world_steps_per_s"]
            out[f"{engine}_service_vs_rollout"] = served / rollout
            out[f"{engine}_alone_vs_rollout"] = (
                out[f"{engine}_alone"]["world_steps_per_s"] / rollout
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
            "warp svc/rollout": r["warp_service_vs_rollout"],
        }
        for n, r in results.items()
    ]
    data = {
        "physics_dt": dt,
        "stream": "/v1/ws?rate=30&format=json (all worlds, one client)",
        "rollout": "mujoco.rollout.Rollout(nthread=usable cores), before and after, averaged",
        "results": results,
        "errors": errors,
    }
    return Result(rows, data, ["target: native served >= 0.9x raw rollout at 1024 worlds"])


def _default_step() -> tuple[int, float]:
    from service.physics import tick_timing

    return tick_timing(common.CONTROL_HZ, common.PHYSICS_DT)


@section(11, "capacity_engines", "Real-time capacity per engine, one 30 Hz subscriber")
def capacity_engines(ctx: Context) -> Result:
    """Per engine: doubling then bisection over realtime servers, one subscriber of all worlds."""
    window, warmup, refine = ctx.pick((30.0, 3.0, 2), (10.0, 2.0, 1))
    starts = {"mujoco": 128, "warp": 64}
    data: dict[str, Any] = {
        "rtf_goal": RTF_GOAL,
        "window_s": window,
        "stream": "/v1/ws?worlds=0-(n-1)&rate=30, one subscriber",
    }
    rows: list[dict[str, Any]] = []
    notes = []
    for engine in ENGINE_NAMES:
        errors: dict[str, str] = {}

        def measure(n: int, engine: str = engine, errors: dict = errors) -> dict[str, Any]:
            t0 = time.perf_counter()
            try:
                with ctx.serve(n, "realtime", env={"ARMFLEET_ENGINE": engine}) as server:
                    res = asyncio.run(_measure_realtime(server, window, warmup, per_subscriber=n))
            except Exception as exc:
                errors[str(n)] = f"{type(exc).__name__}: {exc}"
                return {"nworld": n, "realtime_factor": None, "error": errors[str(n)]}
            ctx.say(
                f"  {engine:>6} {n:>6} worlds  RTF {res['realtime_factor']:.3f} "
                f"({time.perf_counter() - t0:.1f} s)"
            )
            return res

        start = ctx.worlds[0] if ctx.worlds else starts[engine]
        best, candidates = capacity_search(measure, start, 4096, refine)
        data[engine] = {"capacity_worlds": best, "candidates": candidates, "errors": errors}
        rows += [
            {
                "engine": engine,
                "worlds": r["nworld"],
                "RTF": r.get("realtime_factor"),
                "min 1 s RTF": r.get("min_loop_rtf_1s"),
                "frames/s": r.get("frames_per_s_per_subscriber_mean"),
                "ok": r.get("passed"),
            }
            for r in candidates
        ]
        held = best if best is not None else "none"
        notes.append(f"{engine}: {held} worlds at RTF >= {RTF_GOAL}")
    return Result(rows, data, notes)


@section(12, "physics_step", "Physics step: before (2.083 ms) vs today's default, engine alone")
def physics_step(ctx: Context) -> Result:
    """Each engine alone at the old and the new step: ticks/s and 60 Hz worlds that rate holds."""
    from service.physics import tick_timing

    sizes = ctx.sizes((64, 1024), (64,))
    min_time = ctx.pick(3.0, 1.0)
    steps = {
        "old": tick_timing(common.CONTROL_HZ, common.OLD_PHYSICS_DT),
        "new": _default_step(),
    }

    def one(n: int) -> dict[str, Any]:
        out: dict[str, Any] = {"nworld": n}
        for engine in ENGINE_NAMES:
            for label, (_, dt) in steps.items():
                out[f"{engine}_{label}"] = _engine_rate(engine, n, dt, min_time)
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

    from service.engine import WorldBatch

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
