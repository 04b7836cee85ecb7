"""`armfleet capacity`: how many worlds this machine holds in real time, in about a minute.

Why a command of its own: how many worlds a machine holds depends on its cores, their speed and
what else runs there, so a figure measured on another machine does not answer it. This measures
here, with the model as served:

1. **The limit**: raw ``mujoco.rollout`` of the served model on every core (the native engine's
   solver and step), as worlds at 60 Hz; read in a 0.5 s block at the start and again before
   every server start, the best block being the limit (bench/rollout_limit.py says why).
2. **Per engine** (native MuJoCo, MuJoCo Warp on the CPU, and MuJoCo Warp on CUDA where a GPU
   is present): a server of N0 worlds (a share of the limit) in fast mode with one 30 Hz
   subscriber of every world, 2 s: N0 x ticks/s / 60, a little under, is the prediction. The
   same server then runs in realtime mode with that subscriber, 10 s (unless the prediction is
   under N0: a new server of N starts instead); then new servers search
   from there (`how_many_sizes.next_size`): a miss predicts from the rate it kept, a hold from
   how busy the sim thread was, never above the prediction; three realtime runs at most (two
   more while none has held), and
   a run 5% short of real time after 4 s stops there.
3. ``--check``: the server that held each answer, kept up paused meanwhile, runs it again for
   10 s after every engine is measured.

Servers start as `armfleet serve` starts by default, in realtime mode, so that the event loop
and the threads it starts (the frame thread, the sockets' writers) give the cores to the ticks
first as a user's service does (core/process/priority.py: only a service started in realtime
lowers them; one started paused, as this command's were, streamed at the ticks' priority), and
are paused at once and between runs, so one kept for the check takes nothing from the runs
after it; a server start (about 2 s native, 8 s Warp on a quiet 2-core box)
is what a run costs beside its window, so the probe's server runs the first realtime window
too.

Why 10 s windows (the old command ran 30 s checks): a size the machine cannot hold falls
behind steadily, so its shortfall grows with the window while the reading's error does not
(one tick in 600, and the milliseconds of the two /v1/info reads): 10 s tells RTF 0.99 from
1.00. What a longer window adds is an average over the box's own hiccups (another process
taking a core for a second), which are the box's and not the service's; the check, a second
window a minute later, is what shows that the answer was not one lucky window.

Printed as worlds and as a ratio to the limit; the JSON (machine, load, every run) goes to
``bench/results/capacity.json`` or ``--out``. Section 11 (bench/capacity.py) is the slow,
careful version of step 2 for native MuJoCo; this is the quick answer.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from bench import common
from bench.how_many_report import _rows, report
from bench.how_many_sizes import MAX_RUNS, RESOLUTION, UNDER, _floor8, capped, next_size
from bench.rollout_limit import RolloutLimit
from bench.service_bench import RTF_GOAL
from bench.service_probe import FrameCounter, measure_realtime, timed_info

ABORT_BELOW = 0.95  # a run this far short of real time after `abort_after_s` is a miss


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
    Engine("warp", "MuJoCo Warp on the CPU (--engine warp)", "warp", "cpu", 0.2),
)
# A GPU holds tens of thousands: one JSON subscriber of every world would measure the client.
CUDA_ENGINE = Engine(
    "warp_cuda", "MuJoCo Warp on CUDA (--device cuda)", "warp", "cuda", 16.0, "binary", 4096
)


@dataclass(frozen=True)
class Timing:
    """How long each step runs: full, or `--quick` (a test, a first look)."""

    limit_block_s: float  # one rollout block (one before every server start)
    probe_warmup_s: float  # fast mode: from ready to the window
    probe_window_s: float
    warmup_s: float  # realtime: from ready to the window
    window_s: float  # realtime: the window a size holds or misses in
    check_window_s: float  # --check: the answer run again, on a server of its own
    abort_after_s: float  # a realtime run clearly short of real time stops after this long


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


FULL = Timing(0.5, 1.0, 2.0, 1.5, 10.0, 10.0, 4.0)
QUICK = Timing(0.2, 0.5, 1.0, 1.0, 3.0, 3.0, 1.5)


async def _switch(server: common.Served, mode: str) -> None:
    async with httpx.AsyncClient(timeout=60) as client:
        path = "/v1/sim/pause" if mode == "paused" else "/v1/sim/mode"
        body = None if mode == "paused" else {"mode": mode}
        (await client.post(f"{server.url}{path}", json=body)).raise_for_status()


async def _fast(server: common.Served, window: float, warmup: float, fmt: str) -> dict[str, Any]:
    """Fast mode with one 30 Hz subscriber of every world: served ticks/s over `window`;
    paused again after."""
    counter = FrameCounter()
    reader = asyncio.create_task(counter.run(f"{server.ws_url}/v1/ws?rate=30&format={fmt}"))
    try:
        await _switch(server, "fast")
        async with httpx.AsyncClient(timeout=60) as client:
            await asyncio.sleep(warmup)
            t0, info0 = await timed_info(client, server.url)
            await asyncio.sleep(window)
            t1, info1 = await timed_info(client, server.url)
        await _switch(server, "paused")
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
        "ready_s": server.ready_s,
        "stream_error": counter.error,
    }


def realtime_on(server: common.Served, engine: Engine, window: float, timing: Timing) -> dict:
    """`server` in realtime mode, one 30 Hz subscriber of every world: RTF over `window`
    (stopped early on a clear miss); paused again after, so that a server kept for the
    check takes no time from the runs after it."""

    async def measured() -> dict[str, Any]:
        await _switch(server, "realtime")
        try:
            return await measure_realtime(
                server,
                window,
                timing.warmup_s,
                check_every=1.0,
                abort_below=ABORT_BELOW,
                abort_after=timing.abort_after_s,
                per_subscriber=server.nworld,
                fmt=engine.fmt,
            )
        finally:
            await _switch(server, "paused")

    res = asyncio.run(measured())
    res["held"] = res["realtime_factor"] >= RTF_GOAL and not res["aborted_early"]
    return res


class _Servers:
    """The servers of one command: each started in realtime mode (as users start it: see the
    module docstring) and paused at once; the one holding an engine's answer stays up (paused)
    for `--check`, the others stop as soon as they are measured."""

    def __init__(self) -> None:
        self._stacks: dict[int, contextlib.ExitStack] = {}

    def start(self, engine: Engine, n: int) -> common.Served:
        stack = contextlib.ExitStack()
        env = {"ARMFLEET_ENGINE": engine.engine}
        server = stack.enter_context(common.served(n, "realtime", engine.device, env))
        self._stacks[id(server)] = stack
        asyncio.run(_switch(server, "paused"))
        return server

    def stop(self, server: common.Served | None) -> None:
        if server is not None and id(server) in self._stacks:
            self._stacks.pop(id(server)).close()

    def close(self) -> None:
        for stack in self._stacks.values():
            stack.close()
        self._stacks.clear()


def engine_capacity(
    engine: Engine,
    limit: RolloutLimit,
    timing: Timing,
    say: Callable[[str], None],
    servers: _Servers,
    first: int | None = None,
    max_worlds: int | None = None,
) -> tuple[dict[str, Any], common.Served | None]:
    """Fast mode at N0 predicts N; realtime on the same server at N0, then on new servers
    from there, bisects towards the most held. Returns the result and the server that holds
    the answer (kept up, paused, for the check)."""
    n = n0 = min(
        first or max(engine.floor, _floor8(engine.first_share * limit.worlds())),
        max_worlds or 10**9,
    )
    beside = limit.worlds(limit.read(f"{engine.key} {n0}"))
    server = servers.start(engine, n0)
    probe = asyncio.run(_fast(server, timing.probe_window_s, timing.probe_warmup_s, engine.fmt))
    predicted = _floor8(n0 * probe["ticks_per_s"] / common.CONTROL_HZ * UNDER)
    say(
        f"  {engine.key}: fast mode at {n0} worlds: {probe['ticks_per_s']:.1f} ticks/s "
        f"-> {predicted} worlds predicted"
    )
    runs: list[dict[str, Any]] = []
    lo = hi = kept = None
    if predicted < n0 * (1 - RESOLUTION) and predicted >= 1:  # N0 would miss: start at N
        servers.stop(server)
        n = predicted
        beside = limit.worlds(limit.read(f"{engine.key} {n}"))
        server = servers.start(engine, n)
    while True:
        res = realtime_on(server, engine, timing.window_s, timing)
        res["limit_worlds_beside"] = beside
        runs.append(res)
        if res["held"]:  # the most held so far: its server stays for the check
            servers.stop(kept)
            lo, kept = n, server
        else:
            hi = min(hi or n, n)
            servers.stop(server)
        say(
            f"  {engine.key}: realtime at {n} worlds: RTF {res['realtime_factor']:.3f} "
            f"over {res['wall_s']:.0f} s, sim thread busy {res.get('tick_share') or 0:.2f} "
            f"({'held' if res['held'] else 'missed'})"
        )
        nxt = capped(next_size(n, res, lo, hi), n, predicted, max_worlds)
        if nxt is None or len(runs) >= MAX_RUNS + (2 if lo is None else 0):
            break
        n = nxt
        beside = limit.worlds(limit.read(f"{engine.key} {n}"))
        server = servers.start(engine, n)
    result = {
        "engine": engine.engine,
        "device": engine.device,
        "label": engine.label,
        "format": engine.fmt,
        "fast": [probe],
        "predicted": predicted,
        "runs": runs,
        "worlds": lo,
    }
    return result, kept


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
    rollout = RolloutLimit(timing.limit_block_s)
    servers = _Servers()
    try:
        rollout.read("start")
        say(
            f"  limit: raw mujoco.rollout, {rollout.threads} threads, {rollout.solver}: "
            f"{rollout.best:,.0f} world-steps/s = {rollout.worlds():,.0f} worlds at 60 Hz "
            "(read again before every run)"
        )
        results: dict[str, Any] = {}
        kept: dict[str, common.Served | None] = {}
        for engine in engines:
            try:
                res, kept[engine.key] = engine_capacity(
                    engine, rollout, timing, say, servers, ask.first, ask.max_worlds
                )
            except Exception as exc:  # one engine failing (e.g. Warp's kernels) loses that one
                res = {
                    "label": engine.label,
                    "worlds": None,
                    "error": f"{type(exc).__name__}: {exc}",
                }
                say(f"  {engine.key}: FAILED: {res['error']}")
            results[engine.key] = res
        if ask.check:
            for key, res in results.items():
                server = kept.get(key)
                if server is None:
                    continue
                engine = next(e for e in engines if e.key == key)
                beside = rollout.worlds(rollout.read(f"check {key}"))
                c = realtime_on(server, engine, timing.check_window_s, timing)
                res["check"] = c | {"limit_worlds_beside": beside}
                say(
                    f"  check {key}: {res['worlds']} worlds again for {c['wall_s']:.0f} s: RTF "
                    f"{c['realtime_factor']:.3f} ({'held' if c['held'] else 'MISSED'})"
                )
    finally:
        servers.close()
        rollout.close()
    limit = rollout.summary()
    for res in results.values():  # against the best block of the whole command
        res["ratio_to_limit"] = res["worlds"] / limit["worlds"] if res.get("worlds") else None
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
        # how its servers ran (this changed: they used to start paused, see _Servers)
        "servers_start": "realtime, paused at once and between runs",
        "timing": timing.__dict__,
        "limit": limit,
        "engines": results,
        "rows": _rows(limit, results),
    }


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
