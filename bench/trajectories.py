"""Section 21: trajectories, tracking and scale, on both engines.

1. Tracking (in process, paused and stepped tick by tick, so the figures are simulated-time
   facts): a 2 s trajectory through three points for all six arm joints; the largest path error
   |actual - desired| over the run, and the distance to the last point 0.5 s after the end.
   Then the CPU seconds a tick of 1024 worlds takes in process without and with a trajectory
   holding the pose on every world (what the trajectory work costs, whatever else loads the
   machine).
2. Fast mode at 1024 worlds (``armfleet serve --mode fast``): ticks/s with no trajectory, with
   every world running a 300 s, 150-point trajectory that holds the pose (all the trajectory
   work, the physics unchanged) and one that swings the arm ±0.3 rad, windows interleaved in
   one run so drift on a shared machine falls on all; ratios are against no trajectory.
3. 10,000 trajectories started over HTTP in one batch call (``POST /v1/trajectories`` with
   ``worlds: "0-9999"``, native engine, paused): the call's wall time, then one tick stepped
   with all of them sampled.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import httpx
import numpy as np

from bench.registry import Context, Result, section

ARM_DELTAS = (  # three points around home, clear of the table and the arm itself
    (0.7, (0.5, -0.3, 0.3, 0.3, -0.4, 0.6)),
    (1.4, (0.9, -0.5, 0.6, -0.2, 0.3, 1.2)),
    (2.0, (0.4, -0.2, 0.2, 0.3, 0.5, 0.3)),
)
SCALE_WORLDS = 1024
BATCH_WORLDS = 10_000


def _three_point_body(home: np.ndarray) -> dict[str, Any]:
    """The tracking trajectory with velocities (cubic): central slopes, zero at the end."""
    times = [0.0] + [t for t, _ in ARM_DELTAS]
    pos = [home] + [home + np.array(d) for _, d in ARM_DELTAS]
    points = []
    for i in range(1, len(pos)):
        j = min(i + 1, len(pos) - 1)
        vel = (pos[j] - pos[i - 1]) / (times[j] - times[i - 1]) if i < len(pos) - 1 else 0 * home
        points.append(
            {"positions": pos[i].tolist(), "velocities": vel.tolist(), "time_from_start": times[i]}
        )
    return {"points": points}


def _long_body(home: np.ndarray, names: list[str], swing: float) -> dict[str, Any]:
    """150 points, 2 s apart, swinging every arm joint ±`swing` rad: 300 s of work per world."""
    sign = np.array([1.0, -0.7, 0.7, 1.0, -1.0, 1.0])
    points = [
        {
            "positions": (home + swing * sign * (1 if i % 2 else -1)).tolist(),
            "time_from_start": 2.0 * i,
        }
        for i in range(1, 151)
    ]
    return {"joint_names": names, "points": points}


def tracking(engine: str) -> dict[str, Any]:
    """Largest path error and the error 0.5 s after the end, stepping a paused loop."""
    from service.core.commands.control import Control
    from service.core.commands.trajectory import parse
    from service.core.sim.loop import SimLoop
    from service.core.sim.settings import SimSettings
    from service.core.sim.types import Mode
    from service.engines.choice import build_batch
    from service.engines.settings import EngineSettings

    # one process, one thread
    batch = build_batch(EngineSettings(kind=engine, shards=1), SimSettings(worlds=2))
    loop = SimLoop(batch, Mode.PAUSED)
    control = Control(loop)
    loop.start()
    try:
        names = batch.spec.names[:6]
        body = {"joint_names": names, **_three_point_body(batch.home_target[:6])}
        started = control.start_trajectory([0], parse(batch.spec, body), "http")[0]
        worst = 0.0
        while loop.tick < started.end_tick:
            loop.step(1).result()
            status = control.trajectories.status(0)
            if status.feedback_tick == loop.tick:
                worst = max(worst, float(np.abs(status.error).max()))
        outcome = control.trajectories.status(0)
        loop.step(round(0.5 * batch.control_hz)).result()
        last = np.array(body["points"][-1]["positions"])
        final = float(np.abs(loop.latest.position[0, :6] - last).max())
        return {"max_path_error": worst, "final_error": final, "outcome": outcome.state.value}
    finally:
        loop.stop()
        batch.close()


def cpu_ratio(engine: str, ticks: int, rounds: int) -> dict[str, Any]:
    """CPU seconds per tick of 1024 worlds in process, no trajectory vs one holding the pose on
    every world (rounds interleaved): the trajectory work's cost, robust to a loaded machine in
    a way wall-clock rates are not (what other processes take is not counted)."""
    from service.core.commands.control import Control
    from service.core.commands.trajectory import parse
    from service.core.sim.loop import SimLoop
    from service.core.sim.types import Mode

    if engine == "warp":
        from service.engines.warp import WorldBatch

        batch = WorldBatch(SCALE_WORLDS)
    else:
        from service.engines.native import NativeBatch

        batch = NativeBatch(SCALE_WORLDS, nthread=1)
    loop = SimLoop(batch, Mode.PAUSED)
    control = Control(loop)
    loop.start()
    everyone = list(range(SCALE_WORLDS))
    body = _long_body(batch.home_target[:6], batch.spec.names[:6], 0.0)
    spec = parse(batch.spec, body)
    cpu: dict[str, list[float]] = {"none": [], "hold": []}
    try:
        loop.step(3).result()  # warm-up
        for _ in range(rounds):
            for kind in cpu:
                control.reset(None, "http")
                if kind == "hold":
                    control.start_trajectory(everyone, spec, "http")
                loop.step(1).result()
                t0 = time.process_time()
                loop.step(ticks).result()
                cpu[kind].append((time.process_time() - t0) / ticks)
    finally:
        loop.stop()
        batch.close()
    return {"cpu_s_per_tick": cpu, "ratio": float(np.mean(cpu["none"]) / np.mean(cpu["hold"]))}


def _ticks_per_s(url: str, window: float) -> float:
    def tick() -> tuple[float, int]:
        t0 = time.perf_counter()
        n = httpx.get(f"{url}/v1/info", timeout=60).json()["tick"]
        return (t0 + time.perf_counter()) / 2, n

    a = tick()
    time.sleep(window)
    b = tick()
    return (b[1] - a[1]) / (b[0] - a[0])


# What runs on every world in the fast-mode windows: nothing; a trajectory whose 150 points all
# hold the home pose (every tick sampled, staged and applied to every world, so all of the
# trajectory work, while the physics stays bit-identical to no trajectory); one that swings the
# arm ±0.3 rad (the same work plus the physics of 1024 arms in motion).
FAST_KINDS = {"none": None, "hold": 0.0, "move": 0.3}


def fast_ratio(ctx: Context, engine: str, window: float, rounds: int) -> dict[str, Any]:
    """ticks/s with each of FAST_KINDS on every world, windows interleaved (A B C A B C)."""
    env = {"ARMFLEET_ENGINE": engine}
    with ctx.serve(SCALE_WORLDS, "fast", env=env) as srv:
        http = httpx.Client(base_url=srv.url, timeout=120)
        names = [j["name"] for j in srv.info["joints"]][:6]
        home = np.array([j["home"] for j in srv.info["joints"]][:6])
        rates: dict[str, list[float]] = {k: [] for k in FAST_KINDS}
        _ticks_per_s(srv.url, window / 2)  # warm-up
        for _ in range(rounds):
            for kind, swing in FAST_KINDS.items():
                http.post("/v1/reset").raise_for_status()
                if swing is not None:
                    trajectory = _long_body(home, names, swing)
                    body = {"worlds": f"0-{SCALE_WORLDS - 1}", "trajectory": trajectory}
                    http.post("/v1/trajectories", json=body).raise_for_status()
                rates[kind].append(_ticks_per_s(srv.url, window))
                if swing is not None:
                    last = http.get(f"/v1/worlds/{SCALE_WORLDS - 1}/trajectory").json()
                    assert last["state"] == "running", last
        http.post("/v1/reset").raise_for_status()
    mean = {k: float(np.mean(v)) for k, v in rates.items()}
    return {
        "ticks_per_s": rates,
        "ratio_hold": mean["hold"] / mean["none"],
        "ratio_move": mean["move"] / mean["none"],
        "substeps": srv.info.get("substeps"),
    }


def batch_start(ctx: Context) -> dict[str, Any]:
    """One POST /v1/trajectories for 10,000 worlds (native engine, paused), then one tick."""
    with ctx.serve(BATCH_WORLDS, "paused", env={"ARMFLEET_ENGINE": "mujoco"}) as srv:
        http = httpx.Client(base_url=srv.url, timeout=300)
        names = [j["name"] for j in srv.info["joints"]][:6]
        home = np.array([j["home"] for j in srv.info["joints"]][:6])
        body = {"joint_names": names, **_three_point_body(home)}
        payload = {"worlds": f"0-{BATCH_WORLDS - 1}", "trajectory": body}
        t0 = time.perf_counter()
        r = http.post("/v1/trajectories", json=payload)
        call_s = time.perf_counter() - t0
        r.raise_for_status()
        started = r.json()
        t1 = time.perf_counter()
        http.post("/v1/sim/step", json={"ticks": 1}).raise_for_status()
        tick_s = time.perf_counter() - t1
        last = http.get(f"/v1/worlds/{BATCH_WORLDS - 1}/trajectory").json()
        return {
            "started": started["started"],
            "call_s": call_s,
            "first_tick_s": tick_s,
            "distinct_ids": len(set(started["ids"])) == BATCH_WORLDS,
            "last_world_progress": last["progress"],
        }


@section(21, "trajectories")
def trajectories(ctx: Context) -> Result:
    """Trajectories: tracking, 1024 worlds in fast mode, 10k batch start"""
    rows: list[dict[str, Any]] = []
    data: dict[str, Any] = {"errors": {}}

    def measure(key: str, run: Callable[[], dict[str, Any]], row: Callable[[dict], str]) -> None:
        try:
            got = data[key] = run()
        except Exception as exc:  # one part failing keeps the others' figures
            data["errors"][key] = f"{type(exc).__name__}: {exc}"
            return
        ctx.say(f"  {key}: {got}")
        rows.append({"measure": key, "value": row(got)})

    def tracked(t: dict[str, Any]) -> str:
        err, final = t["max_path_error"], t["final_error"]
        return f"max path error {err:.4f} rad; +0.5 s: {final:.5f} rad ({t['outcome']})"

    def ratio(f: dict[str, Any]) -> str:
        m = {k: np.mean(v) for k, v in f["ticks_per_s"].items()}
        return (
            f"none {m['none']:.1f}, hold {m['hold']:.1f} ({f['ratio_hold']:.3f}x), "
            f"move {m['move']:.1f} ticks/s ({f['ratio_move']:.3f}x)"
        )

    def cpu(c: dict[str, Any]) -> str:
        none, hold = (np.mean(c["cpu_s_per_tick"][k]) * 1000 for k in ("none", "hold"))
        return f"{hold:.1f} vs {none:.1f} CPU ms a tick: {c['ratio']:.3f}x throughput"

    window, rounds = ctx.pick((10.0, 3), (5.0, 2))
    for engine in ("warp", "mujoco"):
        measure(f"tracking {engine}", lambda e=engine: tracking(e), tracked)
    for engine in ("warp", "mujoco"):
        run = lambda e=engine: cpu_ratio(e, *ctx.pick((30, 3), (15, 2)))  # noqa: E731
        measure(f"hold, CPU per tick, {SCALE_WORLDS} worlds {engine}", run, cpu)
    for engine in ("warp", "mujoco"):
        run = lambda e=engine: fast_ratio(ctx, e, window, rounds)  # noqa: E731
        measure(f"fast mode {SCALE_WORLDS} worlds {engine}", run, ratio)
    measure(
        f"{BATCH_WORLDS} trajectories in one HTTP call (mujoco, paused)",
        lambda: batch_start(ctx),
        lambda b: f"{b['call_s'] * 1000:.0f} ms; first tick {b['first_tick_s']:.2f} s",
    )
    notes = [
        f"fast mode: {window:g} s windows, {rounds} per kind, interleaved; hold = a trajectory "
        "holding the pose (all trajectory work, physics identical), move = ±0.3 rad swings "
        "(plus the physics of 1024 arms in motion)"
    ]
    return Result(rows, data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
