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
* a lost actor: one of the shards' actors is killed; how long until its replacement has resumed
  from the last state copy, and how the other shards stepped meanwhile.

Section 15 of ``armfleet bench`` (``--section 15``; on by default with ``--device cuda``), or
``python -m bench.ray_bench --device cuda``. Where the bench runner's dependencies are missing
(the lent GPU machine): ``python -c "import sys; from bench.ray_bench import standalone;
standalone(sys.argv[1:])" --device cuda --out ray_cuda.json``. Ray, Warp and MuJoCo are imported
inside functions so that importing this module stays light.
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


def fast_rate(
    batch: Any, seconds: float, warmup: float = 1.0, snapshot_hz: float = SNAPSHOT_HZ
) -> dict[str, Any]:
    """Ticks/s and world-steps/s stepping flat out with a snapshot every 1/`snapshot_hz` s
    (none when 0: what the shards' compute alone scales to)."""
    period = 1.0 / snapshot_hz if snapshot_hz else float("inf")
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
        # worlds x physics steps, as in section 1
        "world_steps_per_s": round(ticks * batch.substeps * batch.nworld / elapsed, 1),
        "snapshots_with_step": getattr(batch, "prefetched", None),
    }


def round_trip(batch: Any, ticks: int) -> dict[str, Any]:
    """Per-tick cost of the Ray round trip with ticks paced at the batch's control rate."""
    period = batch.tick_dt
    overhead, wall, shard, snap = [], [], [], []
    deadline = time.perf_counter()
    next_snap = deadline
    late = 0
    start = time.perf_counter()
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
        "achieved_hz": round(ticks / (time.perf_counter() - start), 2),
        "late_ticks": late,
        "snapshots_with_step": batch.prefetched,
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
    loss_worlds: int = 0,
) -> dict[str, Any]:
    """Every measurement on one machine, into `out` (saved after each step); returns it."""
    from service.engines.ray_shards import RayBatch, connect
    from service.engines.warp import WorldBatch

    out = {} if out is None else out
    out.update({"device": device, "worlds_per_shard": worlds, "fast": {}, "steps": {}, "rt": {}})

    def both(key: str, batch: Any) -> dict[str, Any]:
        out["fast"][key] = res = fast_rate(batch, seconds)
        out["steps"][key] = fast_rate(batch, seconds / 2, warmup=0.2, snapshot_hz=0)
        return res

    def saved(msg: str) -> None:
        say(msg)
        if save is not None:
            save(out)

    t0 = time.perf_counter()
    # The in-process baseline first: on a cold machine it compiles the kernels the actors load.
    wb = WorldBatch(worlds, device=device)
    say(f"in-process WorldBatch({worlds}) built in {time.perf_counter() - t0:.1f} s")
    both("in_process_1x", wb)
    saved(f"  in-process: {out['fast']['in_process_1x']}")
    del wb
    gc.collect()
    if single_gpu_double:
        wb = WorldBatch(worlds * shards, device=device)
        both("in_process_all_worlds", wb)
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
        res = both(f"ray_{k}_shard", rb)
        res["build_s"] = round(build, 2)
        res["device_name"] = rb.device_name
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
    steps = {k: v["world_steps_per_s"] for k, v in out["steps"].items()}
    out["steps_scaling"] = round(steps[f"ray_{shards}_shard"] / steps["ray_1_shard"], 3)
    out["steps_scaling_vs_in_process"] = round(
        steps[f"ray_{shards}_shard"] / steps["in_process_1x"], 3
    )
    for n in rt_worlds:
        rb = RayBatch(n * shards, shards, device=device)
        out["rt"][str(n * shards)] = round_trip(rb, rt_ticks)
        saved(f"  round trip, {shards} × {n} worlds: {out['rt'][str(n * shards)]}")
        rb.close()
        del rb
        gc.collect()
    if loss_worlds:
        rb = RayBatch(loss_worlds * shards, shards, device=device, checkpoint_s=1.0)
        out["loss"] = lose_one(rb, warm_s=3.0)
        saved(f"  one of {shards} actors killed: {out['loss']}")
        rb.close()
    return out


def lose_one(batch: Any, warm_s: float, limit_s: float = 300.0) -> dict[str, Any]:
    """Kill the last shard's actor after `warm_s` of stepping (state copies every second);
    step on until it is rebuilt: how long that took, and how the other shards fared meanwhile."""
    import ray
    from ray.exceptions import RayActorError

    t0 = time.monotonic()
    while time.monotonic() - t0 < warm_s:
        batch.step(1)
    victim = batch.actors[-1]
    ray.kill(victim, no_restart=True)
    while True:  # ray.kill is asynchronous: from here on, calls on the actor fail
        try:
            ray.get(victim.snapshot.remote())
        except RayActorError:
            break
    t_kill, tick_kill, restored = time.perf_counter(), batch.tick, len(batch.restored)
    steps: list[float] = []
    home = 0
    while len(batch.restored) == restored and time.perf_counter() - t_kill < limit_s:
        t1 = time.perf_counter()
        home = int(batch.step(1).size)
        steps.append(time.perf_counter() - t1)
        if home:
            break
    resumed = batch.restored[restored:]
    return {
        "nworld": batch.nworld,
        "shards": batch.shards,
        "rebuild_s": round(time.perf_counter() - t_kill, 2),
        "ticks_meanwhile": batch.tick - tick_kill,
        "slowest_step_meanwhile_ms": round(max(steps) * 1e3, 2) if steps else None,
        "resumed_from_tick": resumed[0][1] if resumed else None,
        "tick_at_loss": tick_kill,
        "came_back_home": home,
    }


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


def _rows(payload: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per configuration: fast-mode rates, then the 60 Hz round trips."""
    labels = {
        "in_process_1x": "in-process",
        "in_process_all_worlds": "in-process, all",
        "ray_1_shard": "Ray 1 shard",
    }
    rows = []
    for group, title in (("fast", "fast, 30 Hz snapshots"), ("steps", "steps only")):
        one = payload[group].get("ray_1_shard", {}).get("world_steps_per_s")
        for key, res in payload[group].items():
            label = labels.get(key, f"Ray {res['shards']} shards")
            rows.append(
                {
                    "run": f"{title}, {label}",
                    "worlds": res["nworld"],
                    "ticks/s": res["ticks_per_s"],
                    "world-steps/s": round(res["world_steps_per_s"]),
                    "vs Ray 1 shard": round(res["world_steps_per_s"] / one, 2) if one else "",
                    "Ray ms/tick p50": "",
                    "Ray ms/tick p99": "",
                    "snapshot ms p50": "",
                }
            )
    for n, res in payload["rt"].items():
        rows.append(
            {
                "run": f"60 Hz, Ray {res['shards']} shards",
                "worlds": int(n),
                "ticks/s": res["achieved_hz"],
                "world-steps/s": "",
                "vs Ray 1 shard": "",
                "Ray ms/tick p50": res["ray_overhead"]["p50_ms"],
                "Ray ms/tick p99": res["ray_overhead"]["p99_ms"],
                "snapshot ms p50": res["snapshot_fetch"]["p50_ms"],
            }
        )
    return rows


def measure(
    quick: bool, device: str, worlds: int | None, say: Any = print, save: Any = None
) -> dict[str, Any]:
    """The section's work with its default sizes: 2 x 32768 worlds on CUDA, small on the CPU."""
    cuda = device.startswith("cuda")
    per_shard = worlds or (32768 if cuda else (16 if quick else 64))
    small = 64 if cuda else 8
    payload: dict[str, Any] = {"machine": machine()}
    run(
        device,
        per_shard,
        seconds=3.0 if quick else 8.0,
        rt_ticks=120 if quick else 600,
        rt_worlds=sorted({small, per_shard}),
        say=say,
        out=payload,
        save=save,
        loss_worlds=4096 if cuda else 8,
    )
    return payload


try:  # the registry is part of the bench package; the device machine may run this file alone
    from bench.registry import Context, Result, section
except ImportError:  # pragma: no cover
    section = None

if section is not None:

    @section(15, "ray", ("cpu", "cuda"), default_on=("cuda",))
    def ray_shards(ctx: Context) -> Result:
        """Ray shards: one vs two in fast mode; the Ray round trip per tick at 60 Hz"""
        payload = measure(ctx.quick, ctx.device, ctx.worlds[0] if ctx.worlds else None, ctx.say)
        notes = [
            f"two shards / one shard (Ray): {payload['scaling']}x with 30 Hz snapshots, "
            f"{payload['steps_scaling']}x steps only; / in-process one device: "
            f"{payload['scaling_vs_in_process']}x, {payload['steps_scaling_vs_in_process']}x",
            "Ray ms/tick: driver's step wall time minus the slowest shard's own step time; "
            "snapshot: all shards' states into the API process (30 Hz)",
        ]
        loss = payload.get("loss")
        if loss:
            notes.append(
                f"one of {loss['shards']} actors killed ({loss['nworld']} worlds): rebuilt in "
                f"{loss['rebuild_s']} s while the others stepped {loss['ticks_meanwhile']} ticks "
                f"(slowest {loss['slowest_step_meanwhile_ms']} ms); resumed from tick "
                f"{loss['resumed_from_tick']} (lost at {loss['tick_at_loss']})"
            )
        return Result(_rows(payload), data=payload, notes=notes)


def standalone(argv: list[str] | None = None) -> int:
    """Without the bench runner (e.g. on a machine lacking its dependencies): JSON to --out."""
    ap = argparse.ArgumentParser(description="Ray shards benchmark, standalone")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--worlds", type=int, default=None, help="worlds per shard")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=None, help="JSON file to write")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()

    def save(payload: dict[str, Any]) -> None:
        payload["took_s"] = round(time.perf_counter() - t0, 1)
        if a.out:
            with open(a.out, "w") as fh:
                json.dump(payload, fh, indent=1)

    payload = measure(a.quick, a.device, a.worlds, save=save)
    payload["rows"] = _rows(payload)
    save(payload)
    print(json.dumps(payload["rows"], indent=1))
    return 0


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
