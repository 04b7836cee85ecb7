"""Sections 2, 3 and 7: the service as a subprocess, measured from a client.

2. ``service_fast``: ``armfleet serve --mode fast`` with every world streamed to one WebSocket
   client (``/v1/ws?rate=30``); section 7, ``service_fast_binary``, the same with binary frames
   (``&format=binary``). World-steps/s come from the tick advance over wall time (``/v1/info``
   before and after the window; the frames' ticks are reported too) and are compared with the
   engine and raw captured MuJoCo Warp numbers of section 1: the service's overhead.
3. ``realtime_capacity``: the largest batch for which ``realtime`` mode holds a real-time factor
   >= 0.99 over a window, 60 Hz control, ~2 ms physics, one subscriber
   (``/v1/ws?worlds=a-b&rate=30``) per 16 worlds. Doubling from what section 1 predicts (or from
   ``--worlds N``), then bisection; the RTF of every candidate is reported.

The client shares the machine with the server: on a 2-core box its frame handling competes with
the server's threads, as a real co-located client would.

Standalone: ``python -m bench.service_bench --section 2 --worlds 16 256``.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from typing import Any

from bench.registry import Context, Result, section
from bench.service_probe import WORLDS_PER_SUBSCRIBER, measure_fast, measure_realtime

CPU_SIZES = (1, 16, 64, 256, 1024, 4096)
CPU_SIZES_QUICK = (16, 256)
CUDA_SIZES = (1024, 4096, 16384, 65536)
CUDA_SIZES_QUICK = (1024, 16384)
RTF_GOAL = 0.99

# -- section 2: fast mode ------------------------------------------------------------------------

REFERENCES = {  # section 1's engines the service is compared with, and their column headings
    "engine": "svc/engine",
    "engine_cores": "svc/eng cores",
    "warp_captured": "svc/warp capt",
    "rollout_all": "svc/mj all",
}


def fast(ctx: Context, fmt: str) -> Result:
    """Fast mode at every size, `fmt` frames; ratios to section 1's last results on this device."""
    sizes = ctx.sizes(
        CUDA_SIZES if ctx.cuda else CPU_SIZES, CUDA_SIZES_QUICK if ctx.cuda else CPU_SIZES_QUICK
    )
    duration, warmup = ctx.pick((8.0, 2.0), (3.0, 1.0))
    base = (ctx.earlier("throughput") or {}).get("results", {})

    def one(n: int) -> dict[str, Any]:
        with ctx.serve(n, "fast") as server:
            res = asyncio.run(measure_fast(server, duration, warmup, fmt))
        engines = base.get(str(n), {}).get("engines", {})
        for key in REFERENCES:
            ref = engines.get(key, {}).get("world_steps_per_s")
            res[f"ratio_to_{key}"] = res["world_steps_per_s"] / ref if ref else None
        return res

    results, errors = ctx.each(
        sizes,
        one,
        lambda r: (
            f"{r['world_steps_per_s']:>14,.0f} world-steps/s, {r['frames_per_s']:.1f} frames/s"
        ),
    )
    rows = []
    for n, r in results.items():
        kb = r.get("frame_bytes_mean")
        row = {
            "worlds": int(n),
            "world-steps/s": r["world_steps_per_s"],
            "ticks/s": r["ticks_per_s"],
            "frames/s": r["frames_per_s"],
            "frame KB": None if kb is None else kb / 1e3,
        }
        rows.append(row | {col: r[f"ratio_to_{key}"] for key, col in REFERENCES.items()})
    return Result.per_size(
        rows,
        results,
        errors,
        {
            "mode": "fast",
            "stream": f"/v1/ws?rate=30&format={fmt} (all worlds, one client)",
            "format": fmt,
            "sizes": sizes,
            "duration_s": duration,
            "warmup_s": warmup,
        },
    )


@section(2, "service_fast", ("cpu", "cuda"))
def service_fast(ctx: Context) -> Result:
    """Service, fast mode, all worlds streamed at 30 Hz, JSON frames"""
    return fast(ctx, "json")


@section(7, "service_fast_binary", ("cpu", "cuda"), default_on=("cuda",))
def service_fast_binary(ctx: Context) -> Result:
    """Service, fast mode, all worlds streamed at 30 Hz, binary frames"""
    return fast(ctx, "binary")


# -- section 3: real-time capacity ------------------------------------------------------------


def _round_to(x: float, step: int) -> int:
    return max(1, round(x / step) * step)


def capacity_search(
    measure: Callable[[int], dict[str, Any]],
    start: int = 16,
    max_worlds: int = 4096,
    refine: int = 2,
    goal: float = RTF_GOAL,
) -> tuple[int | None, list[dict[str, Any]]]:
    """Doubling (or halving) from `start` until pass/fail brackets, then `refine` bisections.

    `measure(n)` returns a dict with `realtime_factor`. Returns (largest passing n or None,
    every candidate's result in the order measured).
    """
    tried: dict[int, dict[str, Any]] = {}

    def passes(n: int) -> bool:
        if n not in tried:
            tried[n] = {**measure(n), "order": len(tried)}
            tried[n]["passed"] = (tried[n].get("realtime_factor") or 0.0) >= goal
        return tried[n]["passed"]

    lo: int | None = None
    hi: int | None = None
    n = max(1, start)
    if passes(n):
        lo = n
        while n * 2 <= max_worlds:
            n *= 2
            if passes(n):
                lo = n
            else:
                hi = n
                break
    else:
        hi = n
        while n > 1:
            n //= 2
            if passes(n):
                lo = n
                break
            hi = n
    for _ in range(refine):
        if lo is None or hi is None:
            break
        step = 8 if lo >= 16 else 1
        mid = _round_to((lo + hi) / 2, step)
        if mid <= lo or mid >= hi:
            break
        if passes(mid):
            lo = mid
        else:
            hi = mid
    return lo, sorted(tried.values(), key=lambda r: r["order"])


def start_from_throughput(throughput: dict[str, Any] | None, control_hz: float = 60.0) -> int:
    """Where doubling starts: the power of two at or below half of what section 1 predicts.

    The prediction is the largest min(n, engine world-steps/s at n / steps a world needs per
    second) over the measured sizes; without section 1, 16.
    """
    if not throughput:
        return WORLDS_PER_SUBSCRIBER
    need = control_hz * throughput.get("substeps", 8)  # physics steps per world per second
    best = 0.0
    for n, entry in throughput.get("results", {}).items():
        wsps = entry.get("engines", {}).get("engine", {}).get("world_steps_per_s")
        if wsps:
            best = max(best, min(int(n), wsps / need))
    if best < 2:
        return 1
    return 2 ** math.floor(math.log2(best / 2))


@section(3, "realtime_capacity")
def realtime_capacity(ctx: Context) -> Result:
    """Real-time capacity (RTF >= 0.99)

    Doubling from what section 1 predicts, then bisection; every candidate is reported."""
    window, warmup, refine = ctx.pick((60.0, 3.0, 2), (10.0, 2.0, 1))
    start = ctx.worlds[0] if ctx.worlds else start_from_throughput(ctx.earlier("throughput"))
    max_worlds = 4096
    errors: dict[str, str] = {}

    def measure(n: int) -> dict[str, Any]:
        t0 = time.perf_counter()
        try:
            with ctx.serve(n, "realtime") as server:
                res = asyncio.run(measure_realtime(server, window, warmup))
        except Exception as exc:
            errors[str(n)] = f"{type(exc).__name__}: {exc}"
            ctx.say(f"  {n:>6} worlds  realtime FAILED: {exc}")
            return {"nworld": n, "realtime_factor": None, "error": errors[str(n)]}
        verdict = "ok" if res["realtime_factor"] >= RTF_GOAL else "short"
        ctx.say(
            f"  {n:>6} worlds  realtime RTF {res['realtime_factor']:.3f} over "
            f"{res['wall_s']:.1f} s ({verdict}{', stopped early' if res['aborted_early'] else ''};"
            f" {time.perf_counter() - t0:.1f} s)"
        )
        return res

    best, candidates = capacity_search(measure, start, max_worlds, refine)
    rows = [
        {
            "worlds": r["nworld"],
            "RTF": r.get("realtime_factor"),
            "min 1 s RTF": r.get("min_loop_rtf_1s"),
            "wall s": r.get("wall_s"),
            "stopped early": r.get("aborted_early"),
            "subscribers": r.get("subscribers"),
            "frames/s/sub": r.get("frames_per_s_per_subscriber_mean"),
            "ok": r.get("passed"),
        }
        for r in candidates
    ]
    data = {
        "mode": "realtime",
        "rtf_goal": RTF_GOAL,
        "window_s": window,
        "warmup_s": warmup,
        "worlds_per_subscriber": WORLDS_PER_SUBSCRIBER,
        "stream": "/v1/ws?worlds=a-b&rate=30, one per 16 worlds",
        "search": {"start": start, "max_worlds": max_worlds, "refine": refine},
        "capacity_worlds": best,
        "candidates": candidates,
        "errors": errors,
    }
    note = f"capacity: {best if best is not None else 'none'} worlds at RTF >= {RTF_GOAL}"
    return Result(rows, data, [f"{note} over {window:.0f} s windows"])


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
