"""Section 17: why the engine's tick measured faster than "raw captured MuJoCo Warp".

Section 1 compared the engine's captured tick with `substeps` raw ``mjw.step`` calls captured
into one graph; both step the same model with the same per-world buffers, yet at 65,536 worlds
the engine measured 1.67x the raw graph. In one process, on the device, this section times
every tick from `home` of:

* ``engine``: ``WorldBatch.step(1)`` (its graph: substeps + kinematics + gather; a fault read);
* ``raw_reset``: ``put_data`` of home, one step (loads the kernels), ``reset_data_keyframe``
  back to home (as the engine does), then the captured substeps: section 1's baseline now;
* ``raw_as_bench``: section 1's old recipe: a second of uncaptured ``mjw.step`` first.

A tick's cost is not constant: the solver iterates until the slowest world converges, and how
many iterations that takes changes as the worlds settle after `home`. The means per quarter of
the window show it; compared over the same ticks from home the engine and the raw graph cost
the same. Also measured: device memory per world (free memory before and after building a
batch) and a batch of 2^20 worlds built and stepped (the largest this section tries).

Standalone: ``python -m bench.warp_baseline --device cuda --worlds 16384 --worlds 65536``.
"""

from __future__ import annotations

import gc
import statistics
import time
from collections.abc import Callable
from typing import Any

from bench.registry import Context, Result, section

ROUNDS = 2


def _stats(d: Any) -> dict[str, float]:
    """Work the last step did: solver iterations (mean, max over worlds), contacts, constraints."""
    niter = d.solver_niter.numpy()
    nefc = d.nefc.numpy()
    return {
        "solver_niter_mean": float(niter.mean()),
        "solver_niter_max": int(niter.max()),
        "nacon": int(d.nacon.numpy()[0]),
        "nefc_mean": float(nefc.mean()),
    }


def _free(device: Any) -> int:
    import warp as wp

    wp.synchronize_device(device)
    gc.collect()
    return int(device.free_memory)


def _raw(n: int, device: Any, variant: str, substeps: int) -> tuple[Any, Any, Any]:
    """(model, data, graph) of one raw variant, ready to replay."""
    import mujoco_warp as mjw
    import numpy as np
    import warp as wp

    from bench.baselines import home_key, physics_dt, raw_warp

    m, d = raw_warp(n, str(device), physics_dt()[1])
    with wp.ScopedDevice(device):
        mjw.step(m, d)  # loads every kernel (capture needs them)
        if variant == "raw_reset":
            mjw.reset_data_keyframe(m, d, wp.array(np.full(n, home_key(), np.int32), dtype=int))
        if variant == "raw_as_bench":
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < 1.0:
                mjw.step(m, d)
            wp.synchronize_device(device)
        with wp.ScopedCapture(device=device) as cap:
            for _ in range(substeps):
                mjw.step(m, d)
    return m, d, cap.graph


def _series(step: Callable[[], Any], sync: Callable[[], Any], ticks: int) -> list[float]:
    """ms of each of `ticks` consecutive ticks, each timed to completion."""
    out = []
    for _ in range(ticks):
        t0 = time.perf_counter()
        step()
        sync()
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def measure(n: int, device_name: str, ticks: int) -> dict[str, Any]:
    """Engine vs raw captured ticks from `home`, tick by tick over the same simulated window."""
    import warp as wp

    from bench.baselines import physics_dt
    from service.engines.warp import WorldBatch

    device = wp.get_device(device_name)
    substeps = physics_dt()[0]
    out: dict[str, Any] = {"nworld": n, "substeps": substeps, "ticks": ticks}
    free0 = _free(device)
    batch = WorldBatch(n, device=device_name)
    out["engine_bytes"] = free0 - _free(device)
    series = {"engine": _series(lambda b=batch: b.step(1), lambda: None, ticks)}
    stats = {"engine": _stats(batch._d)}
    del batch
    gc.collect()
    for variant in ("raw_reset", "raw_as_bench"):
        m, d, g = _raw(n, device, variant, substeps)
        sync = lambda: wp.synchronize_device(device)  # noqa: E731
        series[variant] = _series(lambda g=g: wp.capture_launch(g), sync, ticks)
        stats[variant] = _stats(d)
        del m, d, g
        gc.collect()
    out["ms_per_tick"] = series
    out["last_tick_stats"] = stats
    # Windows of simulated time: the cost of a tick moves as the worlds settle.
    q = max(1, ticks // 4)
    out["window_mean_ms"] = {
        k: [statistics.fmean(v[i : i + q]) for i in range(0, ticks - q + 1, q)]
        for k, v in series.items()
    }
    late = {k: statistics.fmean(v[q:]) for k, v in series.items()}
    out["mean_ms_after_first_quarter"] = late
    out["engine_vs"] = {k: v / late["engine"] for k, v in late.items() if k != "engine"}
    per_world = out["engine_bytes"] / n
    out["engine_bytes_per_world"] = per_world
    out["device_total_bytes"] = int(device.total_memory)
    out["largest_batch_estimate"] = int(0.9 * device.total_memory / per_world)
    return out


LARGEST_TRIES = (1 << 20, 3 << 18, 1 << 19, 3 << 17)


def _largest_in_subprocess(device: str, n: int) -> dict[str, Any]:
    import json
    import subprocess
    import sys

    code = (
        "import json, sys; from bench.warp_baseline import largest; "
        f"print('RESULT ' + json.dumps(largest({device!r}, {n})))"
    )
    try:
        proc = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, timeout=240
        )
    except subprocess.TimeoutExpired:
        return {"nworld": n, "fits": False, "error": "timed out"}
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    return {"nworld": n, "fits": False, "error": proc.stderr[-400:]}


def largest(device_name: str, n: int, ticks: int = 5) -> dict[str, Any]:
    """Build a batch of `n` worlds and step it: does it fit, what does a tick cost."""
    import warp as wp

    from service.engines.warp import WorldBatch

    device = wp.get_device(device_name)
    free0 = _free(device)
    t0 = time.perf_counter()
    try:
        batch = WorldBatch(n, device=device_name)
    except Exception as exc:
        return {"nworld": n, "fits": False, "error": f"{type(exc).__name__}: {exc}"}
    build_s = time.perf_counter() - t0
    used = free0 - _free(device)
    per = _series(lambda b=batch: b.step(1), lambda: None, ticks)
    out = {
        "nworld": n,
        "fits": True,
        "build_s": build_s,
        "bytes": used,
        "bytes_per_world": used / n,
        "free_after_bytes": _free(device),
        "ms_per_tick": per,
        "world_steps_per_s": n * batch.substeps / (statistics.median(per) / 1e3),
        "faults": int(batch.snapshot().faults.sum()),
    }
    del batch
    gc.collect()
    return out


@section(17, "warp_baseline", ("cuda",))
def warp_baseline(ctx: Context) -> Result:
    """Engine vs raw captured MuJoCo Warp: what differs"""
    sizes = ctx.sizes((16384, 65536), (4096,))
    ticks = ctx.pick(240, 60)
    results, errors = ctx.each(
        sizes,
        lambda n: measure(n, ctx.device, ticks),
        lambda r: "  ".join(f"{k} {v:.2f} ms" for k, v in r["mean_ms_after_first_quarter"].items()),
    )
    rows = []
    for n, r in results.items():
        for k, ms in r["mean_ms_after_first_quarter"].items():
            st = r["last_tick_stats"][k]
            rows.append(
                {
                    "worlds": int(n),
                    "variant": k,
                    "ms/tick": ms,
                    "by quarter": " ".join(f"{x:.1f}" for x in r["window_mean_ms"][k]),
                    "variant/engine": r["engine_vs"].get(k, 1.0),
                    "solver iters": f"{st['solver_niter_mean']:.2f}/{st['solver_niter_max']}",
                }
            )
    data: dict[str, Any] = {"results": results, "errors": errors}
    if results and not ctx.quick:
        data["largest"] = tried = []
        for n in LARGEST_TRIES:  # each in a fresh process: a clean device
            tried.append(_largest_in_subprocess(ctx.device, n))
            ctx.say(f"  {n:>8} worlds: {tried[-1]}")
            if tried[-1].get("fits"):
                break
    notes = [
        "ms/tick: mean over the ticks after the first quarter, from home; raw_reset is the "
        "baseline section 1 now uses, raw_as_bench its old recipe (a second of uncaptured "
        "steps first)"
    ]
    return Result(rows, data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
