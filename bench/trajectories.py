"""Section 21: trajectories, tracking and scale, on both engines.

1. Tracking (in process, paused and stepped tick by tick, so the figures are simulated-time
   facts): a 2 s trajectory through three points for all six arm joints; the largest path error
   |actual - desired| over the run, and the distance to the last point 0.5 s after the end.
2. Fast mode at 1024 worlds (``armfleet serve --mode fast``): ticks/s with no trajectory, then
   with every world running a 300 s, 150-point trajectory, alternating windows in one run
   (A B A B) so drift on a shared machine falls on both; the ratio is mean(B) / mean(A).
3. 10,000 trajectories started over HTTP in one batch call (``POST /v1/trajectories`` with
   ``worlds: "0-9999"``, native engine, paused): the call's wall time, then one tick stepped
   with all of them sampled.
"""

from __future__ import annotations

import time
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


def _long_body(home: np.ndarray, names: list[str]) -> dict[str, Any]:
    """150 points, 2 s apart, swinging every arm joint ±0.3 rad: 300 s of work per world."""
    swing = np.array([0.3, -0.2, 0.2, 0.3, -0.3, 0.3])
    points = [
        {"positions": (home + swing * (1 if i % 2 else -1)).tolist(), "time_from_start": 2.0 * i}
        for i in range(1, 151)
    ]
    return {"joint_names": names, "points": points}


def tracking(engine: str) -> dict[str, Any]:
    """Largest path error and the error 0.5 s after the end, stepping a paused loop."""
    from service.core.control import Control, Source
    from service.core.loop import SimLoop
    from service.core.trajectory import parse
    from service.core.types import Mode

    if engine == "warp":
        from service.engines.warp import WorldBatch

        batch = WorldBatch(2)
    else:
        from service.engines.native import NativeBatch

        batch = NativeBatch(2, nthread=1)
    loop = SimLoop(batch, Mode.PAUSED)
    control = Control(loop)
    loop.start()
    try:
        names = batch.spec.names[:6]
        body = {"joint_names": names, **_three_point_body(batch.home_target[:6])}
        started = control.start_trajectory([0], parse(batch.spec, body), Source.HTTP)[0]
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


def _ticks_per_s(url: str, window: float) -> float:
    def tick() -> tuple[float, int]:
        t0 = time.perf_counter()
        n = httpx.get(f"{url}/v1/info", timeout=60).json()["tick"]
        return (t0 + time.perf_counter()) / 2, n

    a = tick()
    time.sleep(window)
    b = tick()
    return (b[1] - a[1]) / (b[0] - a[0])


def fast_ratio(ctx: Context, engine: str, window: float, rounds: int) -> dict[str, Any]:
    """ticks/s without and with a trajectory on every world, windows alternating."""
    env = {"ARMFLEET_ENGINE": engine}
    with ctx.serve(SCALE_WORLDS, "fast", env=env) as srv:
        http = httpx.Client(base_url=srv.url, timeout=120)
        names = [j["name"] for j in srv.info["joints"]][:6]
        home = np.array([j["home"] for j in srv.info["joints"]][:6])
        body = {"worlds": f"0-{SCALE_WORLDS - 1}", "trajectory": _long_body(home, names)}
        plain, moving = [], []
        _ticks_per_s(srv.url, window / 2)  # warm-up
        for _ in range(rounds):
            http.post("/v1/reset").raise_for_status()
            plain.append(_ticks_per_s(srv.url, window))
            http.post("/v1/trajectories", json=body).raise_for_status()
            moving.append(_ticks_per_s(srv.url, window))
            running = http.get(f"/v1/worlds/{SCALE_WORLDS - 1}/trajectory").json()["state"]
            assert running == "running", running
        http.post("/v1/reset").raise_for_status()
    a, b = float(np.mean(plain)), float(np.mean(moving))
    return {
        "without_ticks_per_s": plain,
        "with_ticks_per_s": moving,
        "ratio": b / a,
        "world_steps_per_s_with": b * SCALE_WORLDS * srv.info.get("substeps", 1),
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


@section(21, "trajectories", "Trajectories: tracking, 1024 worlds in fast mode, 10k batch start")
def trajectories(ctx: Context) -> Result:
    rows: list[dict[str, Any]] = []
    data: dict[str, Any] = {"errors": {}}
    for engine in ("warp", "mujoco"):
        try:
            t = data[f"tracking_{engine}"] = tracking(engine)
            ctx.say(f"  tracking {engine}: {t}")
            rows.append(
                {
                    "measure": f"tracking, {engine}",
                    "value": f"max path error {t['max_path_error']:.4f} rad; "
                    f"+0.5 s: {t['final_error']:.5f} rad ({t['outcome']})",
                }
            )
        except Exception as exc:
            data["errors"][f"tracking_{engine}"] = f"{type(exc).__name__}: {exc}"
    window, rounds = ctx.pick((10.0, 3), (5.0, 2))
    for engine in ("warp", "mujoco"):
        try:
            f = data[f"fast_{engine}"] = fast_ratio(ctx, engine, window, rounds)
            ctx.say(f"  fast {engine}: {f}")
            rows.append(
                {
                    "measure": f"fast mode, {SCALE_WORLDS} worlds, {engine}",
                    "value": f"{np.mean(f['with_ticks_per_s']):.1f} vs "
                    f"{np.mean(f['without_ticks_per_s']):.1f} ticks/s: {f['ratio']:.3f}x",
                }
            )
        except Exception as exc:
            data["errors"][f"fast_{engine}"] = f"{type(exc).__name__}: {exc}"
    try:
        b = data["batch_start"] = batch_start(ctx)
        ctx.say(f"  batch start: {b}")
        rows.append(
            {
                "measure": f"{BATCH_WORLDS} trajectories, one HTTP call (mujoco, paused)",
                "value": f"{b['call_s'] * 1000:.0f} ms; first tick {b['first_tick_s']:.2f} s",
            }
        )
    except Exception as exc:
        data["errors"]["batch_start"] = f"{type(exc).__name__}: {exc}"
    notes = ["window " + f"{window:g} s x {rounds} rounds per kind, alternating (A B A B)"]
    return Result(rows, data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
