"""Cells: per-world parameters and entities, what they cost.

* stepping with every listed parameter per world against the scene's shared model, warp and
  native side by side: two batches of the same size built together, measured in alternating
  windows (so that a box that slows down slows both), the ratio batched / shared;
  on warp, the memory the batched fields take per world;
* one request setting the poses (then the parameters) of every world of a served batch
  (native, realtime): the time from sending it to the first state read that carries it
  (read-your-writes waits for the acknowledged tick), with the request's own time beside it;
* the example bin-picking cell (three parts) and the default scene at 256 worlds, native,
  real time, with one 30 Hz subscriber of every world: the real-time factor of each, and the
  CPU the server spent per simulated second (the cores real time takes; the RTF only says
  whether they were free on a machine that other work shares), with the load beside it;
* what one world-step of each costs (native, one thread, the two alternating in one process):
  what the served figures come from, without the server or the load;
* drawing a randomisation for 10,000 worlds (the spec of the docs' guide): the time to draw
  and validate it (what `POST /v1/randomize` spends before anything is staged).

Section 23 of ``armfleet bench`` (``--section 23``), or ``python -m bench.cells [--quick]``.
"""

from __future__ import annotations

import os
import statistics
import time
from types import SimpleNamespace
from typing import Any

from bench.registry import Context, Result, section

SPEC = {
    "entities": {"cube": {"position": [[0.6, 0.8], [0.0, 0.3], [0.78, 0.8]], "yaw": [-3, 3]}},
    "params": {
        "cube.mass": [0.05, 0.5],
        "cube.friction": [0.3, 1.2],
        "elbow_joint.kp": [800, 1200],
    },
}


def _door(batch: Any) -> Any:
    return SimpleNamespace(loop=SimpleNamespace(batch=batch), nworld=batch.nworld, spec=batch.spec)


def every_param(batch: Any) -> list[Any]:
    """A write of every listed parameter for every world (values inside their ranges)."""
    from service.core.commands.params import SetParams, param_table

    table = param_table(batch.robot.mjm, batch.spec.names)
    rows = batch.model_values
    defaults = {n: p.read({f: rows(f)[0] for f in p.fields}) for n, p in table.items()}
    items = []
    for w in range(batch.nworld):
        values = {}
        for name, p in table.items():
            bounds = zip(defaults[name], p.lower, p.upper, strict=True)
            v = [min(max(x * (1.0 + 0.001 * (w % 7)), lo), hi) for x, lo, hi in bounds]
            values[name] = v if p.size > 1 else v[0]
        items.append({"world": w, "params": values})
    return list(SetParams.create(_door(batch), items).writes)


def _build(engine: str, n: int) -> Any:
    if engine == "native":
        from service.engines.native import NativeBatch

        return NativeBatch(n)
    from service.engines.warp import WorldBatch

    return WorldBatch(n)


def stepping(engine: str, n: int, windows: int, ticks: int) -> dict[str, Any]:
    """Ticks/s of the shared model and of every parameter batched, alternating windows."""
    from service.core.sim.batch import TickWrites

    shared, batched = _build(engine, n), _build(engine, n)
    t0 = time.perf_counter()
    batched.write(TickWrites(model=tuple(every_param(batched))))
    write_s = time.perf_counter() - t0
    times: dict[str, list[float]] = {"shared": [], "batched": []}
    for b in (shared, batched):
        b.step(2)  # warm
    for _ in range(windows):
        for name, b in (("shared", shared), ("batched", batched)):
            t0 = time.perf_counter()
            b.step(ticks)
            times[name].append(time.perf_counter() - t0)
    rate = {k: ticks * len(v) / sum(v) for k, v in times.items()}
    # each pair of neighbouring windows gives a ratio; their median is robust to a burst of
    # load from elsewhere on the machine landing in one window
    pairs = [s / b for s, b in zip(times["shared"], times["batched"], strict=True)]
    out = {
        "engine": engine,
        "nworld": n,
        "shared_ticks_per_s": round(rate["shared"], 2),
        "batched_ticks_per_s": round(rate["batched"], 2),
        "ratio": round(statistics.median(pairs), 3),
        "window_ratios": [round(r, 3) for r in pairs],
        "write_all_params_s": round(write_s, 3),
    }
    if engine == "warp":
        fields = [*batched.batched_fields()]
        nbytes = sum(getattr(batched._m, f).capacity for f in fields)
        out["batched_fields"] = fields
        out["bytes_per_world"] = round(nbytes / n)
    for b in (shared, batched):
        b.close()
    return out


def first_tick(n: int) -> dict[str, Any]:
    """A served native batch: one request with every world's pose, then every world's params."""
    import httpx

    from bench import common

    out: dict[str, Any] = {"nworld": n}
    with common.served(n, "realtime", "cpu", {"ARMFLEET_ENGINE": "mujoco"}) as srv:
        http = httpx.Client(base_url=srv.url, timeout=60)
        poses = [
            {"world": w, "name": "cube", "position": [0.7, 0.17, 0.8 + 0.0001 * (w % 100)]}
            for w in range(n)
        ]
        params = [{"world": w, "params": {"cube.mass": 0.1 + 0.0001 * w}} for w in range(n)]
        for what, path, body in (
            ("poses", "/v1/entities", poses),
            ("params", "/v1/params", params),
        ):
            t0 = time.perf_counter()
            ack = http.post(path, json={"writes": body})
            t_ack = time.perf_counter()
            ack.raise_for_status()
            read = "/v1/worlds/{}/entities/cube" if what == "poses" else "/v1/worlds/{}/params"
            got = http.get(read.format(n - 1)).json()  # waits for the acknowledged tick
            t_read = time.perf_counter()
            assert got["tick"] >= ack.json()["tick"]
            out[what] = {
                "request_s": round(t_ack - t0, 4),
                "first_tick_read_s": round(t_read - t0, 4),
                "bytes": len(ack.request.content),
            }
    return out


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system, every thread) process `pid` has run so far."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cell_rtf(n: int, scene: str | None, window: float) -> dict[str, Any]:
    """Real-time factor of a served native batch of `scene` (None: the default one) with ONE
    30 Hz subscriber of every world, as the capacity section measures it; and the server's CPU
    seconds per simulated second over the same span (None where /proc is not there)."""
    import asyncio

    from bench import common
    from bench.service_probe import measure_realtime

    env = {"ARMFLEET_ENGINE": "mujoco", **({"ARMFLEET_SCENE": scene} if scene else {})}
    load = [round(x, 2) for x in os.getloadavg()]
    with common.served(n, "realtime", "cpu", env) as srv:
        pid = srv.server.process.pid
        proc = os.path.exists(f"/proc/{pid}/stat")
        cpu0, info0 = _cpu_s(pid) if proc else 0.0, srv.get_info()[1]
        got = asyncio.run(measure_realtime(srv, window, warmup=2.0, per_subscriber=n))
        cpu1, info1 = _cpu_s(pid) if proc else 0.0, srv.get_info()[1]
    sim_s = (info1["tick"] - info0["tick"]) / info1["control_hz"]
    cores = (cpu1 - cpu0) / sim_s if proc and sim_s > 0 else None
    keep = ("realtime_factor", "min_loop_rtf_1s", "frames_per_s_per_subscriber_min")
    return {
        "nworld": n,
        "scene": scene or "default",
        **{k: got[k] for k in keep},
        "cpu_s_per_sim_s": None if cores is None else round(cores, 3),
        "loadavg_at_start": load,
    }


def step_cost(scenes: dict[str, str | None], n: int, windows: int, ticks: int) -> dict[str, Any]:
    """CPU microseconds per world-step of each scene: native batches of `n` worlds on one thread,
    settled for 2 s, stepped in alternating windows (a burst of load lands in one window, and
    the median of each scene's windows leaves it out)."""
    from service.engines.native import NativeBatch

    batches = {
        k: NativeBatch(n, nthread=1, **({"model_path": p} if p else {})) for k, p in scenes.items()
    }
    for b in batches.values():
        b.step(120)
    spent: dict[str, list[float]] = {k: [] for k in batches}
    for _ in range(windows):
        for k, b in batches.items():
            t0 = time.process_time()
            b.step(ticks)
            spent[k].append((time.process_time() - t0) / (ticks * n * b.substeps))
    return {k: round(statistics.median(v) * 1e6, 2) for k, v in spent.items()}


def randomize_draw(n: int) -> dict[str, Any]:
    """Draw and validate a randomisation of `n` worlds (no engine stepped: the command alone)."""
    from service.core.commands.randomize import Randomize
    from service.core.sim.robot import load_robot

    robot = load_robot()
    batch = SimpleNamespace(robot=robot, spec=robot.spec, nworld=n)
    t0 = time.perf_counter()
    cmd = Randomize.create(_door(batch), None, 1, SPEC)
    seconds = time.perf_counter() - t0
    writes = len(cmd.entities.writes) + len(cmd.params.writes)
    return {"nworld": n, "seconds": round(seconds, 3), "writes": writes}


@section(23, "cells")
def cells(ctx: Context) -> Result:
    """Cells: per-world parameters batched vs shared, writes to 1024 worlds"""
    n = ctx.worlds[0] if ctx.worlds else ctx.pick(1024, 256)
    windows, ticks = ctx.pick((10, 4), (4, 3))
    rows, data = [], {"stepping": [], "errors": {}}
    for engine in ("native", "warp"):
        try:
            r = stepping(engine, n, windows, ticks)
        except Exception as exc:  # one failure loses one row
            data["errors"][engine] = f"{type(exc).__name__}: {exc}"
            continue
        data["stepping"].append(r)
        ctx.say(f"  {engine}: batched / shared {r['ratio']}")
        rows.append(
            {
                "measure": f"{engine}, {n} worlds, every parameter per world",
                "value": f"{r['batched_ticks_per_s']} vs {r['shared_ticks_per_s']} ticks/s",
                "ratio": r["ratio"],
            }
        )
    try:
        data["first_tick"] = ft = first_tick(n)
        for what in ("poses", "params"):
            rows.append(
                {
                    "measure": f"{what} of {n} worlds in one request → first tick read",
                    "value": f"{ft[what]['first_tick_read_s'] * 1000:.0f} ms "
                    f"(request {ft[what]['request_s'] * 1000:.0f} ms)",
                    "ratio": "",
                }
            )
    except Exception as exc:
        data["errors"]["first_tick"] = f"{type(exc).__name__}: {exc}"
    from mjcf import MJCF_DIR

    example = str(MJCF_DIR / "examples" / "bin_picking.xml")
    data["cell_rtf"] = []
    names = {None: "default scene (1 cube)", example: "bin-picking cell (3 parts)"}
    for scene in (None, example):
        try:
            r = cell_rtf(256, scene, ctx.pick(15.0, 6.0))
        except Exception as exc:
            data["errors"][f"rtf {scene}"] = f"{type(exc).__name__}: {exc}"
            continue
        data["cell_rtf"].append(r)
        cores = r["cpu_s_per_sim_s"]
        rows.append(
            {
                "measure": f"{names[scene]}, 256 worlds, native, one 30 Hz subscriber: RTF"
                " (server CPU per simulated second; load at start)",
                "value": f"{r['realtime_factor']:.3f} ("
                + ("-" if cores is None else f"{cores:.2f} cores")
                + f"; load {r['loadavg_at_start'][0]})",
                "ratio": "",
            }
        )
    data["step_us"] = us = step_cost(
        {"default": None, "cell": example}, 64, *ctx.pick((9, 20), (5, 10))
    )
    for key, scene in (("default", None), ("cell", example)):
        rows.append(
            {
                "measure": f"{names[scene]}: one world-step, native, one thread (CPU)",
                "value": f"{us[key]} µs",
                "ratio": "" if scene is None else round(us[key] / us["default"], 2),
            }
        )
    data["randomize"] = rz = randomize_draw(10_000)
    rows.append(
        {
            "measure": "randomize 10,000 worlds: draw and validate",
            "value": f"{rz['seconds']} s",
            "ratio": "",
        }
    )
    notes = [
        "ratio: ticks/s with every listed parameter given per world over ticks/s of the shared "
        "model: the median over pairs of neighbouring windows, the two batches alternating",
        "cores: the served batch's CPU seconds per simulated second, what real time takes; "
        "the RTF holds 1.0 while that many cores are free, whatever else the machine runs",
        "one world-step: the cell's ratio is to the default scene's",
    ]
    warp = next((r for r in data["stepping"] if r["engine"] == "warp"), None)
    if warp:
        notes.append(f"warp batched fields: {warp['bytes_per_world']} bytes per world")
    return Result(rows, data=data, notes=notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
