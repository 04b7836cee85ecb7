"""`armfleet capacity`: how many worlds this machine holds in real time, in about a minute.

Why a command of its own: how many worlds a machine holds depends on its cores, their speed and
what else runs there, so a figure measured on another machine does not answer it. This measures
here, with the model as served:

1. **The limit**: raw ``mujoco.rollout`` of the served model on every core (the native engine's
   solver and step), as worlds at 60 Hz: world-steps/s over the steps one world needs a second.
   The best of a few short blocks (bench.baselines.Rollout).
2. **Per engine** (native MuJoCo, MuJoCo Warp on the CPU, and MuJoCo Warp on CUDA where a GPU
   is present): ``armfleet serve --mode fast`` at a first guess N0 with one 30 Hz subscriber
   of every world measures the served tick rate; N = N0 x ticks/s / 60 (a little under) is the
   prediction (probed once more at N when it is far from N0), and ``--mode realtime`` at N
   with that subscriber for a short window verifies it (RTF >= 0.99,
   bench.service_probe.measure_realtime); a miss steps N down (twice at most).
3. ``--check``: each engine's answer run again right after, for a longer window: the answer
   holds when RTF >= 0.99 there too.

Printed as worlds and as a ratio to the limit; the JSON (machine, load, every run) goes to
``bench/results/capacity.json`` or ``--out``. Section 11 (bench/capacity.py) is the slow,
careful version of step 2 for native MuJoCo; this is the quick answer.
"""

from __future__ import annotations

import asyncio
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from bench import common
from bench.service_bench import RTF_GOAL
from bench.service_probe import FrameCounter, measure_realtime, timed_info

LIMIT_WORLDS = 1024  # batch size at which raw rollout is timed (bench/capacity.py's)
UNDER = 0.97  # the prediction from fast mode, a little under (realtime waits between ticks)
STEP_DOWNS = 2  # a miss steps N down at most this often
NEAR = 0.25  # a prediction within this share of the probe's size needs no second probe


@dataclass(frozen=True)
class Engine:
    """One way of serving: its name in the output, its `serve` environment, the device, the
    share of the limit to probe fast mode at, and the frame format of the subscriber."""

    key: str
    label: str
    engine: str  # ARMFLEET_ENGINE
    device: str
    first_share: float  # N0 = this x the limit (at least `floor`)
    fmt: str = "json"
    floor: int = 16


CPU_ENGINES = (
    Engine("mujoco", "native MuJoCo (--engine mujoco)", "mujoco", "cpu", 0.9),
    Engine("warp", "MuJoCo Warp on the CPU (--engine warp)", "warp", "cpu", 0.3),
)
# A GPU holds tens of thousands: one JSON subscriber of every world would measure the client.
CUDA_ENGINE = Engine(
    "warp_cuda", "MuJoCo Warp on CUDA (--device cuda)", "warp", "cuda", 16.0, "binary", 4096
)


@dataclass(frozen=True)
class Timing:
    """How long each step runs: full, or `--quick` (a test, a first look)."""

    limit_block_s: float
    limit_blocks: int
    fast_window_s: float
    warmup_s: float
    window_s: float
    check_window_s: float


@dataclass(frozen=True)
class Ask:
    """What `armfleet capacity` was asked: the engines (None: every one here), `--quick`,
    `--check`, the fast-mode probe size (`--worlds`; None: a share of the limit) and
    `--max-worlds`."""

    engines: Sequence[str] | None = None
    quick: bool = False
    check: bool = False
    first: int | None = None
    max_worlds: int | None = None


FULL = Timing(1.0, 3, 3.0, 2.0, 10.0, 30.0)
QUICK = Timing(0.3, 2, 1.5, 1.0, 3.0, 5.0)


def _floor8(x: float) -> int:
    """Worlds to try: whole multiples of 8 from 16 up (rounded down), else at least 1."""
    return max(1, int(x)) if x < 16 else int(x // 8) * 8


def _below(n: int, rtf: float) -> int:
    """The next N after a miss at `n` with `rtf`: what that rate holds, a little under, and
    always fewer than `n`."""
    return max(1, min(_floor8(n * min(rtf, 1.0) * UNDER), n - (8 if n >= 24 else 1)))


def rollout_limit(timing: Timing) -> dict[str, Any]:
    """Raw rollout of the served model on every core: world-steps/s and worlds at 60 Hz."""
    import mujoco

    from bench.baselines import Rollout, physics_dt

    _, dt = physics_dt()
    steps_per_world_s = common.CONTROL_HZ * round(1 / (common.CONTROL_HZ * dt))
    cores = common.usable_cores()
    rollout = Rollout(LIMIT_WORLDS, cores, dt)
    try:
        rollout.block(timing.limit_block_s / 2)  # warm: the worlds settle from home
        blocks = [rollout.block(timing.limit_block_s) for _ in range(timing.limit_blocks)]
        solver = mujoco.mjtSolver(int(rollout.mjm.opt.solver)).name.removeprefix("mjSOL_")
    finally:
        rollout.close()
    best = max(blocks)
    return {
        "threads": cores,
        "batch": LIMIT_WORLDS,
        "solver": solver.lower(),
        "physics_dt": dt,
        "world_steps_per_s": best,
        "world_steps_per_s_blocks": blocks,
        "worlds": best / steps_per_world_s,
        "steps_per_world_s": steps_per_world_s,
    }


async def _fast(server: common.Served, window: float, warmup: float, fmt: str) -> dict[str, Any]:
    """Fast mode with one 30 Hz subscriber of every world: served ticks/s over `window`."""
    counter = FrameCounter()
    url = f"{server.ws_url}/v1/ws?rate=30&format={fmt}"
    reader = asyncio.create_task(counter.run(url))
    try:
        async with httpx.AsyncClient(timeout=60) as client:
            await asyncio.sleep(warmup)
            t0, info0 = await timed_info(client, server.url)
            await asyncio.sleep(window)
            t1, info1 = await timed_info(client, server.url)
    finally:
        reader.cancel()
        await asyncio.gather(reader, return_exceptions=True)
    ticks = info1["tick"] - info0["tick"]
    return {
        "nworld": server.nworld,
        "ticks_per_s": ticks / (t1 - t0),
        "world_steps_per_s": common.world_steps(ticks, server.nworld, info1["substeps"])
        / (t1 - t0),
        "wall_s": t1 - t0,
        "stream_error": counter.error,
    }


def _serve(engine: Engine, n: int, mode: str):
    return common.served(n, mode, engine.device, {"ARMFLEET_ENGINE": engine.engine})


def realtime_run(engine: Engine, n: int, window: float, warmup: float) -> dict[str, Any]:
    """`n` worlds in realtime mode, one 30 Hz subscriber of every world: RTF over `window`."""
    with _serve(engine, n, "realtime") as server:
        res = asyncio.run(
            measure_realtime(server, window, warmup, per_subscriber=n, fmt=engine.fmt)
        )
    res["held"] = res["realtime_factor"] >= RTF_GOAL
    return res


def engine_capacity(
    engine: Engine,
    limit_worlds: float,
    timing: Timing,
    say: Callable[[str], None],
    first: int | None = None,
    max_worlds: int | None = None,
) -> dict[str, Any]:
    """Fast mode at N0 predicts N; realtime at N verifies it, stepping down on a miss."""
    n0 = first or max(engine.floor, _floor8(engine.first_share * limit_worlds))
    if max_worlds:
        n0 = min(n0, max_worlds)
    probes: list[dict[str, Any]] = []
    n = n0
    # A tick has a part that does not grow with the worlds, so a rate measured far from N
    # predicts it poorly: a second probe at the first prediction when that is far from N0.
    for _ in range(2):
        with _serve(engine, n, "fast") as server:
            fast = asyncio.run(_fast(server, timing.fast_window_s, timing.warmup_s, engine.fmt))
        probes.append(fast)
        n = _floor8(fast["nworld"] * fast["ticks_per_s"] / common.CONTROL_HZ * UNDER)
        if max_worlds:
            n = min(n, max_worlds)
        say(
            f"  {engine.key}: fast mode at {fast['nworld']} worlds: "
            f"{fast['ticks_per_s']:.1f} ticks/s -> {n} worlds predicted"
        )
        if abs(n - fast["nworld"]) <= NEAR * fast["nworld"]:
            break
    runs: list[dict[str, Any]] = []
    for attempt in range(STEP_DOWNS + 1):
        res = realtime_run(engine, n, timing.window_s, timing.warmup_s)
        runs.append(res)
        say(
            f"  {engine.key}: realtime at {n} worlds: RTF {res['realtime_factor']:.3f} "
            f"({'held' if res['held'] else 'missed'})"
        )
        if res["held"] or attempt == STEP_DOWNS or n <= 1:
            break
        n = _below(n, res["realtime_factor"])
    held = [r["nworld"] for r in runs if r["held"]]
    return {
        "engine": engine.engine,
        "device": engine.device,
        "label": engine.label,
        "format": engine.fmt,
        "fast": probes,
        "predicted": runs[0]["nworld"],
        "runs": runs,
        "worlds": max(held) if held else None,
    }


def _has_cuda() -> bool:
    """An NVIDIA driver is installed and Warp sees a GPU (Warp is not asked without a driver:
    it would import for seconds and warn)."""
    import ctypes.util

    return ctypes.util.find_library("cuda") is not None and common.cuda_available()


def engines_here(names: Sequence[str] | None) -> list[Engine]:
    """The engines to measure: `names` (keys), else every CPU one and CUDA when a GPU is seen."""
    every = [*CPU_ENGINES]
    if (not names or "warp_cuda" in names) and _has_cuda():
        every.append(CUDA_ENGINE)
    if not names:
        return every
    unknown = set(names) - {e.key for e in (*CPU_ENGINES, CUDA_ENGINE)}
    if unknown:
        raise ValueError(f"engine: unknown {sorted(unknown)}; known: mujoco, warp, warp_cuda")
    return [e for e in every if e.key in names]


def measure(ask: Ask = Ask(), say: Callable[[str], None] = print) -> dict[str, Any]:
    """The whole answer as a JSON-able dict (see the module docstring)."""
    timing = QUICK if ask.quick else FULL
    engines = engines_here(ask.engines)
    started = common.now_iso()
    t0 = time.perf_counter()
    machine = common.machine_info("cuda" if CUDA_ENGINE in engines else "cpu")
    limit = rollout_limit(timing)
    say(
        f"  limit: raw mujoco.rollout, {limit['threads']} threads, {limit['solver']}: "
        f"{limit['world_steps_per_s']:,.0f} world-steps/s = {limit['worlds']:,.0f} worlds at 60 Hz"
    )
    results: dict[str, Any] = {}
    for engine in engines:
        try:
            res = engine_capacity(engine, limit["worlds"], timing, say, ask.first, ask.max_worlds)
        except Exception as exc:  # one engine failing (e.g. Warp's kernels) loses that one
            res = {"label": engine.label, "worlds": None, "error": f"{type(exc).__name__}: {exc}"}
            say(f"  {engine.key}: FAILED: {res['error']}")
        res["ratio_to_limit"] = res["worlds"] / limit["worlds"] if res.get("worlds") else None
        results[engine.key] = res
    if ask.check:
        for key, res in results.items():
            engine = next(e for e in engines if e.key == key)
            if res.get("worlds"):
                c = realtime_run(engine, res["worlds"], timing.check_window_s, timing.warmup_s)
                res["check"] = c
                say(
                    f"  check {key}: {res['worlds']} worlds for {c['wall_s']:.0f} s: RTF "
                    f"{c['realtime_factor']:.3f} ({'held' if c['held'] else 'MISSED'})"
                )
    with_load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return {
        # argv as the bench's result files keep it (bench.figures.command reads it back)
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]],
        "quick": ask.quick,
        "started": started,
        "finished": common.now_iso(),
        "seconds": round(time.perf_counter() - t0, 1),
        "machine": machine,
        "loadavg_at_end": [round(x, 2) for x in with_load] if with_load else None,
        "rtf_goal": RTF_GOAL,
        "timing": timing.__dict__,
        "limit": limit,
        "engines": results,
        "rows": _rows(limit, results),
    }


def _rows(limit: dict[str, Any], results: dict[str, Any]) -> list[dict[str, Any]]:
    """The table of the answer (bench.figures.section_table shows result files by it)."""
    rows: list[dict[str, Any]] = [
        {"what": "rollout limit", "worlds": round(limit["worlds"]), "× the limit": 1.0}
    ]
    for res in results.values():
        held = next((r for r in res.get("runs", []) if r["nworld"] == res.get("worlds")), None)
        rows.append(
            {
                "what": res["label"],
                "worlds": res.get("worlds"),
                "× the limit": res.get("ratio_to_limit"),
                "RTF": held["realtime_factor"] if held else None,
                "check RTF": res["check"]["realtime_factor"] if res.get("check") else None,
            }
        )
    return rows


def report(result: dict[str, Any]) -> str:
    """The answer in words: the limit, then each engine's worlds and ratio to it."""
    m, limit = result["machine"], result["limit"]
    load = m.get("loadavg_at_start")
    lines = [
        f"{m['cpu_model']}, {m['usable_cores']} cores"
        + (f", {m['gpu']}" if m.get("gpu") else "")
        + (f" (load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f})" if load else ""),
        f"  rollout limit: {limit['worlds']:,.0f} worlds at 60 Hz (raw mujoco.rollout of the "
        f"served model, {limit['threads']} threads, {limit['solver']} solver)",
    ]
    for res in result["engines"].values():
        if res.get("worlds"):
            line = (
                f"  {res['label']}: {res['worlds']:,} worlds in real time = "
                f"{res['ratio_to_limit']:.2f}x the limit"
            )
        else:
            line = f"  {res['label']}: none held" + (
                f" ({res['error']})" if res.get("error") else ""
            )
        if res.get("check"):
            c = res["check"]
            line += (
                f"; checked: RTF {c['realtime_factor']:.3f} over {c['wall_s']:.0f} s "
                f"({'held' if c['held'] else 'MISSED'})"
            )
        lines.append(line)
    lines.append(
        f"  (real time: RTF >= {result['rtf_goal']} with one 30 Hz subscriber of every world; "
        f"{result['seconds']:.0f} s)"
    )
    return "\n".join(lines)


def run(
    ask: Ask = Ask(), out: Path | None = None, say: Callable[[str], None] = print
) -> dict[str, Any]:
    """`armfleet capacity`: measure, print the answer, write the JSON; returns the result."""
    say(f"armfleet capacity{' (quick)' if ask.quick else ''}: measuring on this machine ...")
    result = measure(ask, say)
    path = Path(out) if out else common.RESULTS_DIR / "capacity.json"
    result["out"] = str(common.write_json(path.name, result, path.parent))
    say(report(result))
    say(f"wrote {result['out']}")
    return result


def held_everywhere(result: dict[str, Any]) -> bool:
    """Every engine measured holds some worlds (and, when checked, held the check too)."""
    engines = result["engines"].values()
    return all(e.get("worlds") and e.get("check", {"held": True})["held"] for e in engines)
