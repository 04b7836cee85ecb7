"""Ray shards: one shard against two in fast mode, and what the Ray round trip costs per tick.

Two measurements, both of the engine as the loop drives it (no HTTP in between):

* fast mode: step as fast as possible, taking a snapshot at 30 Hz as one subscriber would, for
  the in-process WorldBatch, a RayBatch of one shard and a RayBatch of two shards of the same
  size each (on a 2-GPU machine: one actor per GPU). The scaling figure is two shards' world-steps/s
  over one shard's.
* round trip at 60 Hz: ticks paced to the wall clock; per tick, the driver's wall time of
  `step` minus the slowest shard's own time is what Ray adds (serialising the staged commands,
  scheduling, the reply), reported as p50 / p99 / mean; the snapshot fetch (all shards' states
  into the API process) is timed beside it.

Standalone, e.g. on the GPU machine:
``python -m bench.ray_bench --device cuda --worlds 32768 --out ray_cuda.json``.
Imports Ray, Warp and MuJoCo inside functions so that importing this module stays light.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import statistics
import sys
import time
from typing import Any

SNAPSHOT_HZ = 30.0


def _pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def fast_rate(batch: Any, seconds: float, warmup: float = 1.0) -> dict[str, Any]:
    """Ticks/s and world-steps/s stepping flat out with a snapshot every 1/30 s."""
    period = 1.0 / SNAPSHOT_HZ
    end_warm = time.perf_counter() + warmup
    while time.perf_counter() < end_warm:
        batch.step(1)
    tick0, t0 = batch.tick, time.perf_counter()
    next_snap, snaps = t0, 0
    while (now := time.perf_counter()) - t0 < seconds:
        batch.step(1)
        if now >= next_snap:
            batch.snapshot()
            snaps += 1
            next_snap += period
    elapsed = time.perf_counter() - t0
    ticks = batch.tick - tick0
    return {
        "nworld": batch.nworld,
        "shards": batch.shards,
        "seconds": round(elapsed, 3),
        "ticks": ticks,
        "snapshots": snaps,
        "ticks_per_s": round(ticks / elapsed, 2),
        "world_steps_per_s": round(ticks * batch.nworld / elapsed, 1),
    }


def round_trip(batch: Any, ticks: int) -> dict[str, Any]:
    """Per-tick cost of the Ray round trip with ticks paced at the batch's control rate."""
    period = batch.tick_dt
    overhead, wall, shard, snap = [], [], [], []
    deadline = time.perf_counter()
    next_snap = deadline
    late = 0
    for _ in range(ticks):
        delay = deadline - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        else:
            late += 1
        batch.step(1)
        w, s = batch.last_step
        wall.append(w * 1e3)
        shard.append(s * 1e3)
        overhead.append((w - s) * 1e3)
        now = time.perf_counter()
        if now >= next_snap:
            t0 = time.perf_counter()
            batch.snapshot()
            snap.append((time.perf_counter() - t0) * 1e3)
            next_snap += 1.0 / SNAPSHOT_HZ
        deadline += period

    def stats(xs: list[float]) -> dict[str, float]:
        return {
            "p50_ms": round(statistics.median(xs), 3),
            "p99_ms": round(_pct(xs, 0.99), 3),
            "mean_ms": round(statistics.fmean(xs), 3),
        }

    return {
        "nworld": batch.nworld,
        "shards": batch.shards,
        "control_hz": batch.control_hz,
        "ticks": ticks,
        "late_ticks": late,
        "ray_overhead": stats(overhead),
        "step_wall": stats(wall),
        "slowest_shard": stats(shard),
        "snapshot_fetch": stats(snap),
        "tick_budget_ms": round(period * 1e3, 3),
    }


def run(
    device: str,
    worlds: int,
    seconds: float,
    rt_ticks: int,
    rt_worlds: list[int],
    shards: int = 2,
    single_gpu_double: bool = True,
    say: Any = print,
    out: dict[str, Any] | None = None,
    save: Any = None,
) -> dict[str, Any]:
    """Every measurement on one machine, into `out` (saved after each step); returns it."""
    from service.engine import WorldBatch
    from service.ray_shards import RayBatch, connect

    out = {} if out is None else out
    out.update({"device": device, "worlds_per_shard": worlds, "fast": {}, "rt": {}})

    def saved(msg: str) -> None:
        say(msg)
        if save is not None:
            save(out)

    t0 = time.perf_counter()
    # The in-process baseline first: on a cold machine it compiles the kernels the actors load.
    wb = WorldBatch(worlds, device=device)
    say(f"in-process WorldBatch({worlds}) built in {time.perf_counter() - t0:.1f} s")
    out["fast"]["in_process_1x"] = fast_rate(wb, seconds)
    saved(f"  in-process: {out['fast']['in_process_1x']}")
    del wb
    gc.collect()
    if single_gpu_double:
        wb = WorldBatch(worlds * shards, device=device)
        out["fast"]["in_process_all_worlds"] = fast_rate(wb, seconds)
        saved(f"  in-process, {worlds * shards} worlds: {out['fast']['in_process_all_worlds']}")
        del wb
        gc.collect()

    t1 = time.perf_counter()
    gpus = shards if device.startswith("cuda") else None
    connect("local", num_cpus=max(2, shards), num_gpus=gpus)
    out["ray_start_s"] = round(time.perf_counter() - t1, 2)
    for k in (1, shards):
        t1 = time.perf_counter()
        rb = RayBatch(worlds * k, k, device=device)
        build = time.perf_counter() - t1
        res = fast_rate(rb, seconds)
        res["build_s"] = round(build, 2)
        res["device_name"] = rb.device_name
        out["fast"][f"ray_{k}_shard"] = res
        saved(f"  ray {k} shard(s): {res}")
        rb.close()
        del rb
        gc.collect()
    one = out["fast"]["ray_1_shard"]["world_steps_per_s"]
    many = out["fast"][f"ray_{shards}_shard"]["world_steps_per_s"]
    out["scaling"] = round(many / one, 3)
    out["scaling_vs_in_process"] = round(
        many / out["fast"]["in_process_1x"]["world_steps_per_s"], 3
    )
    for n in rt_worlds:
        rb = RayBatch(n * shards, shards, device=device)
        out["rt"][str(n * shards)] = round_trip(rb, rt_ticks)
        saved(f"  round trip, {shards} × {n} worlds: {out['rt'][str(n * shards)]}")
        rb.close()
        del rb
        gc.collect()
    return out


def machine() -> dict[str, Any]:
    info: dict[str, Any] = {"python": sys.version.split()[0], "platform": platform.platform()}
    info["cpu_count"] = os.cpu_count()
    try:
        import warp as wp

        info["gpus"] = [str(d.name) for d in wp.get_cuda_devices()]
        info["warp"] = wp.config.version
    except Exception as exc:  # report, do not fail the bench over it
        info["gpus"] = f"unknown: {exc}"
    import ray

    info["ray"] = ray.__version__
    return info


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--worlds", type=int, default=64, help="worlds per shard (fast mode)")
    ap.add_argument("--shards", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=8.0, help="fast-mode window per config")
    ap.add_argument("--rt-ticks", type=int, default=600, help="ticks paced at 60 Hz")
    ap.add_argument(
        "--rt-worlds", type=int, nargs="*", default=[64], help="worlds per shard at 60 Hz"
    )
    ap.add_argument("--no-double", action="store_true", help="skip one device with all worlds")
    ap.add_argument("--out", default=None, help="JSON file to write")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    payload: dict[str, Any] = {"machine": machine(), "command": " ".join(sys.argv)}

    def save(data: dict[str, Any]) -> None:
        data["took_s"] = round(time.perf_counter() - t0, 1)
        if a.out:
            with open(a.out, "w") as fh:
                json.dump(data, fh, indent=1)

    run(
        a.device,
        a.worlds,
        a.seconds,
        a.rt_ticks,
        a.rt_worlds,
        a.shards,
        not a.no_double,
        out=payload,
        save=save,
    )
    save(payload)
    print(json.dumps(payload, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
