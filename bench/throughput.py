"""Section 1: engine throughput in world-steps/s against raw MuJoCo Warp and native MuJoCo.

world-steps/s = worlds x physics steps per second. Every engine steps the same model
(mjcf/scene.xml from keyframe `home`, home controls held) with the options the engine sets on it
(the 1/60/8 s step, its solver; taken from a WorldBatch, see `engine_model`, and recorded under
"model" in the JSON) and the same per-world nconmax/njmax:

* ``engine``: ``WorldBatch.step(1)``, the service's captured control tick (`substeps` physics
  steps + kinematics + gather + the fault read-back);
* ``warp_captured``: `substeps` ``mjw.step`` calls captured once with ``wp.ScopedCapture`` and
  replayed with ``wp.capture_launch`` (what the engine's tick costs without its extras), from
  `home` over exactly the engine's warm-up and timed ticks: a tick's cost changes as the worlds
  settle (more solver iterations for the slowest world), so only the same simulated window
  compares like with like (issue 20: timing it after the engine and after a second of
  uncaptured steps made the engine look 1.67x faster at 65,536 worlds);
* ``warp_python``: plain ``mjw.step`` from Python, uncaptured;
* ``rollout_1t`` / ``rollout_<n>t``: native MuJoCo, ``mujoco.rollout.Rollout`` on the calling
  thread and on a pool of all usable cores (on the CPU also when --device cuda).

Standalone: ``python -m bench.throughput --quick --worlds 1 16``.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from bench import common
from bench.baselines import (
    Rollout,
    engine_model,
    finite,
    home_key,
    model_options,
    physics_dt,
    raw_warp,
)
from bench.registry import Context, Result, section

CPU_SIZES = (1, 16, 64, 256, 1024, 4096)
CPU_SIZES_QUICK = (1, 16, 64, 256)
CUDA_SIZES = (1024, 4096, 16384, 65536)
CUDA_SIZES_QUICK = (1024, 16384)

ENGINE = "engine"
ENGINE_CORES = "engine_cores"
WARP_CAPTURED = "warp_captured"
WARP_PYTHON = "warp_python"
ROLLOUT_1T = "rollout_1t"
ROLLOUT_ALL = "rollout_all"  # named rollout_<n>t in the table; the JSON keeps the fixed key

ENGINES = (ENGINE, ENGINE_CORES, WARP_CAPTURED, WARP_PYTHON, ROLLOUT_1T, ROLLOUT_ALL)
DESCRIPTIONS = {
    ENGINE: "armfleet WorldBatch.step (captured tick: substeps + kinematics + gather + fault read)",
    ENGINE_CORES: "armfleet ShardedBatch: the worlds split over all cores, as the service runs",
    WARP_CAPTURED: "raw MuJoCo Warp, `substeps` mjw.step captured (wp.ScopedCapture) and "
    "replayed from home over the engine's simulated window (same warm-up and timed ticks)",
    WARP_PYTHON: "raw MuJoCo Warp, mjw.step called from Python (uncaptured)",
    ROLLOUT_1T: "native MuJoCo, mujoco.rollout.Rollout(nthread=0): the calling thread",
    ROLLOUT_ALL: "native MuJoCo, mujoco.rollout.Rollout(nthread=usable cores)",
}


# -- the engines -------------------------------------------------------------------------------


def _result(timing: common.Timing, steps_per_call: int, nworld: int, **extra: Any) -> dict:
    wsteps = timing.reps * steps_per_call * nworld
    return {
        "world_steps_per_s": wsteps / timing.elapsed,
        "physics_steps_per_s": timing.reps * steps_per_call / timing.elapsed,
        "ms_per_call": timing.per_call * 1e3,
        "steps_per_call": steps_per_call,
        "calls": timing.reps,
        "elapsed_s": timing.elapsed,
        **extra,
    }


# On a GPU the engine and raw captured MuJoCo Warp are timed after this many ticks from home
# (4 simulated seconds): a tick costs ~2.5x more once the worlds have settled than right after
# home (section 17), and the service runs settled; both are timed over the same ticks.
SETTLE_TICKS = 240


def bench_engine(nworld: int, device: str, min_time: float, warmup_time: float) -> dict:
    from service.engines.warp import WorldBatch

    t0 = time.perf_counter()
    batch = WorldBatch(nworld, device=device)
    build_s = time.perf_counter() - t0
    settle = SETTLE_TICKS if device.startswith("cuda") else 1
    timing = common.time_calls(lambda: batch.step(1), min_time, warmup_time, warmup_reps=settle)
    out = _result(
        timing,
        batch.substeps,
        nworld,
        build_s=build_s,
        captured=batch.captured,
        faults=int(batch.snapshot().faults.sum()),
        warmup_calls=timing.warmup,
    )
    return out


def bench_engine_cores(nworld: int, device: str, min_time: float, warmup_time: float) -> dict:
    """The engine as `armfleet serve` builds it on the CPU: one shard per core when big enough."""
    from service.engines.shards import ShardedBatch, auto_shards

    shards = auto_shards(nworld, device)
    if shards < 2:
        return bench_engine(nworld, device, min_time, warmup_time) | {"shards": 1}
    t0 = time.perf_counter()
    batch = ShardedBatch(nworld, shards, device=device)
    build_s = time.perf_counter() - t0
    try:
        timing = common.time_calls(lambda: batch.step(1), min_time, warmup_time)
        faults = int(batch.snapshot().faults.sum())
    finally:
        batch.close()
    return _result(timing, batch.substeps, nworld, build_s=build_s, shards=shards, faults=faults)


def bench_warp(
    nworld: int,
    device: str,
    min_time: float,
    warmup_time: float,
    which: Sequence[str],
    ticks: tuple[int, int] | None = None,
) -> dict[str, dict]:
    """Raw MuJoCo Warp: uncaptured steps on one model/data pair, a captured tick on another.

    A tick's cost depends on the state (the solver iterates until the slowest world converges,
    and that changes as the worlds settle: measured for issue 20), so the captured tick is
    compared with the engine over the same simulated window: from `home` (the engine also
    starts there), `ticks` = (warm-up, timed) ticks as the engine ran them; else by time.
    """
    import mujoco_warp as mjw
    import warp as wp

    substeps, dt = physics_dt()
    out: dict[str, dict] = {}
    dev = wp.get_device(device)

    def sync() -> None:
        wp.synchronize_device(dev)

    with wp.ScopedDevice(dev):
        if WARP_PYTHON in which:
            t0 = time.perf_counter()
            m, d = raw_warp(nworld, device, dt)
            build_s = time.perf_counter() - t0
            mjw.step(m, d)  # the first step loads every kernel
            sync()
            timing = common.time_calls(lambda: mjw.step(m, d), min_time, warmup_time, sync=sync)
            out[WARP_PYTHON] = _result(timing, 1, nworld, build_s=build_s, finite=finite(d))
            del m, d
        if WARP_CAPTURED in which:
            t0 = time.perf_counter()
            m, d = raw_warp(nworld, device, dt)
            build_s = time.perf_counter() - t0
            mjw.step(m, d)  # loads every kernel (capture needs them), then back to home
            mjw.reset_data_keyframe(m, d, wp.array(np.full(nworld, home_key()), dtype=int))
            t1 = time.perf_counter()
            with wp.ScopedCapture(device=dev) as cap:
                for _ in range(substeps):
                    mjw.step(m, d)
            graph = cap.graph
            capture_s = time.perf_counter() - t1
            if ticks is None:
                timing = common.time_calls(
                    lambda: wp.capture_launch(graph), min_time, warmup_time, sync=sync
                )
            else:
                warm, timed = ticks
                timing = common.time_calls(
                    lambda: wp.capture_launch(graph),
                    0.0,
                    0.0,
                    min_reps=timed,
                    warmup_reps=warm,
                    sync=sync,
                    max_reps=timed,
                )
            out[WARP_CAPTURED] = _result(
                timing,
                substeps,
                nworld,
                build_s=build_s,
                capture_s=capture_s,
                warmup_calls=timing.warmup,
                same_window_as_engine=ticks is not None,
                finite=finite(d),
            )
    return out


def bench_rollout(nworld: int, nthread: int, min_time: float, warmup_time: float) -> dict:
    """Native MuJoCo: chained `Rollout.rollout` calls, each continuing from the last state."""
    pool = Rollout(nworld, nthread, physics_dt()[1])
    try:
        timing = common.time_calls(pool.call, min_time, warmup_time)
    finally:
        pool.close()
    return _result(timing, pool.nstep, nworld, nthread=nthread, finite=pool.finite())


# -- the section -------------------------------------------------------------------------------


def _one(name: str, fn: Callable[..., dict]) -> Callable[..., dict[str, dict]]:
    """Wrap a single-engine measurement so that it returns {name: result} like bench_warp."""

    def call(*args: Any) -> dict[str, dict]:
        return {name: fn(*args)}

    return call


def measure_size(
    n: int,
    device: str,
    min_time: float,
    warmup_time: float,
    engines: Sequence[str],
    nthread: int,
    errors: dict[str, str],
    say: Callable[[str], None],
) -> dict[str, Any]:
    """Every engine at `n` worlds: {"engines": {name: result}, "ratios": {...}}."""
    row: dict[str, Any] = {}
    warp_which = [e for e in (WARP_PYTHON, WARP_CAPTURED) if e in engines]
    plan: list[tuple[str, Callable[..., dict[str, dict]], tuple]] = []
    if ENGINE in engines:
        plan.append((ENGINE, _one(ENGINE, bench_engine), (n, device)))
    if ENGINE_CORES in engines and device.startswith("cpu"):
        plan.append((ENGINE_CORES, _one(ENGINE_CORES, bench_engine_cores), (n, device)))
    if warp_which:
        plan.append(("/".join(warp_which), bench_warp, (n, device)))
    if ROLLOUT_1T in engines:
        plan.append((ROLLOUT_1T, _one(ROLLOUT_1T, bench_rollout), (n, 0)))
    if ROLLOUT_ALL in engines:
        plan.append((ROLLOUT_ALL, _one(ROLLOUT_ALL, bench_rollout), (n, nthread)))
    for label, fn, args in plan:
        t0 = time.perf_counter()
        engine = row.get(ENGINE, {})
        window = (engine["warmup_calls"], engine["calls"]) if "warmup_calls" in engine else None
        extra = (warp_which, window) if fn is bench_warp else ()
        try:
            got = fn(*args, min_time, warmup_time, *extra)
        except Exception as exc:  # one engine failing must not lose the others
            errors[f"{n}/{label}"] = f"{type(exc).__name__}: {exc}"
            say(f"  {n:>6} worlds  {label:<28} FAILED: {exc}")
            continue
        finally:
            gc.collect()
        for name, res in got.items():
            row[name] = res
            say(
                f"  {n:>6} worlds  {name:<14} {res['world_steps_per_s']:>14,.0f} "
                f"world-steps/s  ({time.perf_counter() - t0:.1f} s)"
            )
    ratios = {}
    base = row.get(ENGINE, {}).get("world_steps_per_s")
    if base:
        for name, res in row.items():
            if name != ENGINE:
                ratios[f"engine_vs_{name}"] = base / res["world_steps_per_s"]
    cores = row.get(ENGINE_CORES, {}).get("world_steps_per_s")
    native_all = row.get(ROLLOUT_ALL, {}).get("world_steps_per_s")
    if cores and native_all:
        ratios["engine_cores_vs_rollout_all"] = cores / native_all
    return {"engines": row, "ratios": ratios}


SHORT = {
    ENGINE: "engine",
    ENGINE_CORES: "eng cores",
    WARP_CAPTURED: "warp capt",
    WARP_PYTHON: "warp py",
}


def short_label(name: str, nthread: int) -> str:
    if name == ROLLOUT_1T:
        return "mj 1t"
    if name == ROLLOUT_ALL:
        return f"mj {nthread}t"
    return SHORT.get(name, name)


def rows(results: dict[str, Any], engines: Sequence[str], nthread: int) -> list[dict[str, Any]]:
    """World-steps/s by size and engine, then the engine's ratio to each other engine."""
    out = []
    for n, entry in results.items():
        row: dict[str, Any] = {"worlds": int(n)}
        for e in engines:
            row[short_label(e, nthread)] = entry["engines"].get(e, {}).get("world_steps_per_s")
        if ENGINE in engines:
            for e in engines:
                if e != ENGINE:
                    row[f"eng/{short_label(e, nthread)}"] = entry["ratios"].get(f"engine_vs_{e}")
        out.append(row)
    return out


@section(1, "throughput", ("cpu", "cuda"))
def throughput(ctx: Context) -> Result:
    """Throughput, world-steps/s (mj = native MuJoCo rollout)

    Every engine at every size; a failing engine is recorded and the others still run."""
    sizes = ctx.sizes(
        CUDA_SIZES if ctx.cuda else CPU_SIZES, CUDA_SIZES_QUICK if ctx.cuda else CPU_SIZES_QUICK
    )
    min_time, warmup_time = ctx.pick((1.5, 0.3), (0.4, 0.1))
    nthread = common.usable_cores()
    substeps, dt = physics_dt()
    errors: dict[str, str] = {}
    results = {
        str(n): measure_size(
            n, ctx.device, min_time, warmup_time, ENGINES, nthread, errors, ctx.say
        )
        for n in sizes
    }
    engines = [e for e in ENGINES if e != ENGINE_CORES or not ctx.cuda]
    return Result.per_size(
        rows(results, engines, nthread),
        results,
        errors,
        {
            "model": model_options(engine_model(ctx.device)[0]),
            "rollout_device": "cpu",
            "rollout_threads": nthread,
            "substeps": substeps,
            "physics_dt": dt,
            "sizes": sizes,
            "min_time_s": min_time,
            "warmup_time_s": warmup_time,
            "engines": {e: DESCRIPTIONS[e] for e in engines},
        },
    )


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
