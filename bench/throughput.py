"""Section 1: engine throughput in world-steps/s against raw MuJoCo Warp and native MuJoCo.

world-steps/s = worlds x physics steps per second. Every engine steps the same model
(mjcf/scene.xml from keyframe `home`, home controls held) with the options the engine sets on it
(the 1/60/8 s step, its solver; taken from a WorldBatch, see `engine_model`, and recorded under
"model" in the JSON) and the same per-world nconmax/njmax:

* ``engine``: ``WorldBatch.step(1)``, the service's captured control tick (`substeps` physics
  steps + kinematics + gather + the fault read-back);
* ``warp_captured``: `substeps` ``mjw.step`` calls captured once with ``wp.ScopedCapture`` and
  replayed with ``wp.capture_launch`` (what the engine's tick costs without its extras);
* ``warp_python``: plain ``mjw.step`` from Python, uncaptured;
* ``rollout_1t`` / ``rollout_<n>t``: native MuJoCo, ``mujoco.rollout.Rollout`` on the calling
  thread and on a pool of all usable cores (on the CPU also when --device cuda).

Standalone: ``python -m bench.throughput --worlds 1 16 --min-time 1``.
"""

from __future__ import annotations

import argparse
import gc
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from bench import common

SECTION = "throughput"
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
    WARP_CAPTURED: "raw MuJoCo Warp, `substeps` mjw.step captured (wp.ScopedCapture) and replayed",
    WARP_PYTHON: "raw MuJoCo Warp, mjw.step called from Python (uncaptured)",
    ROLLOUT_1T: "native MuJoCo, mujoco.rollout.Rollout(nthread=0): the calling thread",
    ROLLOUT_ALL: "native MuJoCo, mujoco.rollout.Rollout(nthread=usable cores)",
}


def physics_dt(control_hz: float = common.CONTROL_HZ, dt: float = common.PHYSICS_DT) -> tuple:
    """(substeps, physics_dt) exactly as WorldBatch derives them."""
    tick_dt = 1.0 / control_hz
    substeps = max(1, round(tick_dt / dt))
    return substeps, tick_dt / substeps


def defaults(quick: bool, device: str) -> dict[str, Any]:
    cuda = device.startswith("cuda")
    if quick:
        sizes = CUDA_SIZES_QUICK if cuda else CPU_SIZES_QUICK
        return {"sizes": sizes, "min_time": 0.4, "warmup_time": 0.1}
    return {"sizes": CUDA_SIZES if cuda else CPU_SIZES, "min_time": 1.5, "warmup_time": 0.3}


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


def bench_engine(nworld: int, device: str, min_time: float, warmup_time: float) -> dict:
    from service.engine import WorldBatch

    t0 = time.perf_counter()
    batch = WorldBatch(nworld, device=device)
    build_s = time.perf_counter() - t0
    timing = common.time_calls(lambda: batch.step(1), min_time, warmup_time)
    out = _result(
        timing,
        batch.substeps,
        nworld,
        build_s=build_s,
        captured=batch.captured,
        faults=int(batch.snapshot().faults.sum()),
    )
    return out


def bench_engine_cores(nworld: int, device: str, min_time: float, warmup_time: float) -> dict:
    """The engine as `armfleet serve` builds it on the CPU: one shard per core when big enough."""
    from service.shards import ShardedBatch, auto_shards

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


def engine_model():
    """(MjModel, home key id) configured exactly as the engine configures its own.

    WorldBatch sets model options (timestep, and whatever else it tunes, e.g. the solver) on
    the MjModel it loads; building a one-world batch without capture and taking its model keeps
    the baselines on the same physics whatever the engine changes. A fresh model each call.
    """
    from service.engine import WorldBatch

    batch = WorldBatch(1, capture=False)
    return batch.robot.mjm, batch.robot.home_key


def model_options(mjm) -> dict[str, Any]:
    """The options that decide the cost of a step, for the JSON."""
    import mujoco

    o = mjm.opt
    return {
        "timestep": o.timestep,
        "solver": mujoco.mjtSolver(o.solver).name,
        "integrator": mujoco.mjtIntegrator(o.integrator).name,
        "cone": mujoco.mjtCone(o.cone).name,
        "iterations": o.iterations,
        "ls_iterations": o.ls_iterations,
        "nq": mjm.nq,
        "nv": mjm.nv,
        "ngeom": mjm.ngeom,
    }


def _raw_warp(nworld: int, device: str, substeps: int, dt: float):
    """(mjw model, mjw data) of the scene at `home`, sized like the engine's."""
    import mujoco
    import mujoco_warp as mjw
    import warp as wp

    from service.engine import NCONMAX, NJMAX

    mjm, home_key = engine_model()
    assert abs(mjm.opt.timestep - dt) < 1e-12, (mjm.opt.timestep, dt)
    mjd = mujoco.MjData(mjm)
    mujoco.mj_resetDataKeyframe(mjm, mjd, home_key)
    mujoco.mj_forward(mjm, mjd)
    with wp.ScopedDevice(device):
        m = mjw.put_model(mjm)
        d = mjw.put_data(mjm, mjd, nworld=nworld, nconmax=NCONMAX, njmax=NJMAX)
    return m, d


def bench_warp(
    nworld: int, device: str, min_time: float, warmup_time: float, which: Sequence[str]
) -> dict[str, dict]:
    """Raw MuJoCo Warp on one model/data pair: uncaptured steps, then a captured tick."""
    import mujoco_warp as mjw
    import warp as wp

    substeps, dt = physics_dt()
    out: dict[str, dict] = {}
    t0 = time.perf_counter()
    m, d = _raw_warp(nworld, device, substeps, dt)
    build_s = time.perf_counter() - t0
    dev = wp.get_device(device)

    def sync() -> None:
        wp.synchronize_device(dev)

    with wp.ScopedDevice(dev):
        # Plain steps first: the first one loads every kernel, which capture needs.
        mjw.step(m, d)
        sync()
        if WARP_PYTHON in which:
            timing = common.time_calls(lambda: mjw.step(m, d), min_time, warmup_time, sync=sync)
            out[WARP_PYTHON] = _result(timing, 1, nworld, build_s=build_s)
        if WARP_CAPTURED in which:
            t1 = time.perf_counter()
            with wp.ScopedCapture(device=dev) as cap:
                for _ in range(substeps):
                    mjw.step(m, d)
            graph = cap.graph
            capture_s = time.perf_counter() - t1
            timing = common.time_calls(
                lambda: wp.capture_launch(graph), min_time, warmup_time, sync=sync
            )
            out[WARP_CAPTURED] = _result(
                timing, substeps, nworld, build_s=build_s, capture_s=capture_s
            )
        qpos = d.qpos.numpy()
        for res in out.values():
            res["finite"] = bool(np.isfinite(qpos).all())
    return out


def bench_rollout(
    nworld: int, nthread: int, min_time: float, warmup_time: float, target_call_s: float = 0.05
) -> dict:
    """Native MuJoCo: chained `Rollout.rollout` calls, each continuing from the last state."""
    import mujoco
    from mujoco import rollout

    _, dt = physics_dt()
    mjm, home_key = engine_model()
    assert abs(mjm.opt.timestep - dt) < 1e-12, (mjm.opt.timestep, dt)
    mjd = mujoco.MjData(mjm)
    mujoco.mj_resetDataKeyframe(mjm, mjd, home_key)
    mujoco.mj_forward(mjm, mjd)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(mjm, spec)
    state0 = np.empty(nstate)
    mujoco.mj_getState(mjm, mjd, state0, spec)

    # Steps per call: enough that the Python call overhead is noise (~target_call_s per call,
    # from the reference figure of ~100k steps/s per core), at most 200 to bound the output.
    est_rate = 1e5 * max(1, nthread)
    nstep = int(min(200, max(1, math.ceil(target_call_s * est_rate / nworld))))
    initial = np.tile(state0, (nworld, 1))
    control = np.tile(mjd.ctrl.copy(), (nworld, nstep, 1))
    states = np.empty((nworld, nstep, nstate))
    datas = [mujoco.MjData(mjm) for _ in range(max(1, nthread))]

    with rollout.Rollout(nthread=nthread) as pool:

        def call() -> None:
            pool.rollout(mjm, datas, initial, control, nstep=nstep, state=states)
            initial[:] = states[:, -1, :]

        timing = common.time_calls(call, min_time, warmup_time)
    return _result(
        timing,
        nstep,
        nworld,
        nthread=nthread,
        finite=bool(np.isfinite(initial).all()),
    )


# -- orchestration -----------------------------------------------------------------------------


def _one(name: str, fn: Callable[..., dict]) -> Callable[..., dict[str, dict]]:
    """Wrap a single-engine measurement so that it returns {name: result} like bench_warp."""

    def call(*args: Any) -> dict[str, dict]:
        return {name: fn(*args)}

    return call


def cuda_available() -> bool:
    import warp as wp

    import service.engine  # noqa: F401  (sets Warp's log level: no banner)

    try:
        return wp.is_cuda_available()
    except Exception:
        return False


def run(
    sizes: Sequence[int],
    device: str = "cpu",
    min_time: float = 1.5,
    warmup_time: float = 0.3,
    engines: Sequence[str] = ENGINES,
    rollout_threads: int | None = None,
    progress: Callable[[str], None] | None = print,
) -> dict[str, Any]:
    """Measure every engine at every size; returns the section's JSON-ready dict."""
    started = common.now_iso()
    nthread = rollout_threads or common.usable_cores()
    substeps, dt = physics_dt()
    results: dict[str, dict[str, Any]] = {}
    errors: dict[str, str] = {}
    say = progress or (lambda _msg: None)
    warp_which = [e for e in (WARP_PYTHON, WARP_CAPTURED) if e in engines]
    for n in sizes:
        row: dict[str, Any] = {}
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
            extra = (warp_which,) if fn is bench_warp else ()
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
        results[str(n)] = {"engines": row, "ratios": ratios}
    data = {
        "device": device,
        "model": model_options(engine_model()[0]),
        "rollout_device": "cpu",
        "rollout_threads": nthread,
        "substeps": substeps,
        "physics_dt": dt,
        "sizes": list(sizes),
        "min_time_s": min_time,
        "warmup_time_s": warmup_time,
        "engines": {e: DESCRIPTIONS[e] for e in engines},
        "results": results,
        "errors": errors,
    }
    return common.section_payload(SECTION, device, data, started)


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


def table(payload: dict[str, Any]):
    """A rich Table of world-steps/s (rows: sizes, columns: engines) and the engine's ratios."""
    from rich import box
    from rich.table import Table

    engines = list(payload["engines"])
    nthread = payload.get("rollout_threads", 0)
    t = Table(
        title=f"1. Throughput, world-steps/s ({payload['device']}; mj = native MuJoCo rollout)",
        box=box.SIMPLE_HEAD,
    )
    t.add_column("worlds", justify="right")
    for e in engines:
        t.add_column(short_label(e, nthread), justify="right")
    others = [e for e in engines if e != ENGINE]
    if ENGINE in engines:
        for e in others:
            t.add_column(f"eng/{short_label(e, nthread)}", justify="right", style="cyan")
    for n, entry in payload["results"].items():
        row = entry["engines"]
        cells = [n] + [common.si(row.get(e, {}).get("world_steps_per_s")) for e in engines]
        if ENGINE in engines:
            cells += [common.ratio(entry["ratios"].get(f"engine_vs_{e}")) for e in others]
        t.add_row(*cells)
    return t


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.throughput", description=__doc__)
    p.add_argument("--worlds", type=int, nargs="+", help="batch sizes (default: by device)")
    p.add_argument("--device", default="cpu", help="cpu or cuda[:N] (Warp engines only)")
    p.add_argument("--quick", action="store_true", help="fewer sizes, shorter timing")
    p.add_argument("--min-time", type=float, help="seconds timed per measurement")
    p.add_argument("--warmup", type=float, help="seconds of warm-up per measurement")
    p.add_argument("--engines", nargs="+", choices=ENGINES, default=list(ENGINES))
    p.add_argument("--threads", type=int, help="threads for rollout_all (default: all cores)")
    p.add_argument("--out", help="JSON file name in bench/results (default throughput.json)")
    args = p.parse_args(argv)
    if args.device.startswith("cuda") and not cuda_available():
        print(f"bench: no CUDA device is available here; --device {args.device} cannot run.")
        return 2
    d = defaults(args.quick, args.device)
    payload = run(
        args.worlds or d["sizes"],
        args.device,
        d["min_time"] if args.min_time is None else args.min_time,
        d["warmup_time"] if args.warmup is None else args.warmup,
        args.engines,
        args.threads,
    )
    name = args.out or f"{SECTION}{common.suffix_for(args.device)}.json"
    path = common.write_json(name, payload)
    common.console().print(table(payload))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
