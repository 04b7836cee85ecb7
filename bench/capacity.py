"""Section 11: how many worlds each engine holds in real time on the CPU, as a share of the limit.

``capacity_engines``: ``armfleet serve --mode realtime --engine mujoco|warp`` with ONE 30 Hz
subscriber of every world (``/v1/ws?worlds=0-(n-1)&rate=30``, JSON, and for native MuJoCo
binary too); a batch passes when the loop's real-time factor over the window is >= 0.99.

The limit is raw ``mujoco.rollout`` on every core at this physics step, as worlds at 60 Hz. A
shared machine's speed drifts by several percent within minutes, so a rollout block is run
next to every candidate (before and after, with no server running) and each candidate is put
against the limit measured beside it; the strict figure divides by the best block of the run.

Native MuJoCo's search starts at 0.9x the limit (issue 20's target) and steps by 5% until a
candidate passes and one fails, then bisects to 16 worlds; warp's doubles from ``--worlds``
(or 64), then bisects. Each candidate also reports where the sim thread's time went
(/metrics): stepping the engine, the loop's own work in ticks, and the time between ticks.

Standalone: ``python -m bench.capacity --quick``.
"""

from __future__ import annotations

import asyncio
import statistics
import time
from collections.abc import Callable
from typing import Any

from bench import common
from bench.engines import _default_step, _Rollout
from bench.registry import Context, Result, section
from bench.service_bench import RTF_GOAL, _measure_realtime, capacity_search

LIMIT_WORLDS = 1024  # batch size at which the rollout limit is measured
TARGET_SHARE = 0.9  # issue 20: native MuJoCo at >= 0.9x the rollout limit
STEP = 0.05  # native search: candidates 5% of the limit apart ...
RESOLUTION = 16  # ... then bisection down to this many worlds


def _round8(x: float) -> int:
    return max(8, round(x / 8) * 8)


def ladder_search(
    measure: Callable[[int], dict[str, Any]], start: int, step: int, resolution: int
) -> tuple[int | None, list[dict[str, Any]]]:
    """Up (or down) from `start` by `step` worlds until one passes and one fails, then bisect
    until they are `resolution` apart. Returns (largest passing n or None, candidates)."""
    tried: dict[int, dict[str, Any]] = {}

    def passes(n: int) -> bool:
        if n not in tried:
            tried[n] = {**measure(n), "order": len(tried)}
            tried[n]["passed"] = (tried[n].get("realtime_factor") or 0.0) >= RTF_GOAL
        return tried[n]["passed"]

    lo: int | None = None
    hi: int | None = None
    n = start
    if passes(n):
        lo = n
        for _ in range(6):
            n += step
            if not passes(n):
                hi = n
                break
            lo = n
    else:
        hi = n
        while n - step >= 8:
            n -= step
            if passes(n):
                lo = n
                break
            hi = n
    while lo is not None and hi is not None and hi - lo > resolution:
        mid = _round8((lo + hi) / 2)
        if mid <= lo or mid >= hi:
            break
        if passes(mid):
            lo = mid
        else:
            hi = mid
    return lo, sorted(tried.values(), key=lambda r: r["order"])


@section(11, "capacity_engines", "Real-time capacity per engine, one 30 Hz subscriber")
def capacity_engines(ctx: Context) -> Result:
    """Per engine and frame format: the largest realtime batch, each candidate beside a limit."""
    window, warmup, block_s = ctx.pick((30.0, 3.0, 1.0), (10.0, 2.0, 0.5))
    _, dt = _default_step()
    steps_per_world_s = common.CONTROL_HZ * round(1 / (common.CONTROL_HZ * dt))
    rollout = _Rollout(LIMIT_WORLDS, common.usable_cores(), dt)
    blocks: list[float] = []  # every rollout block of the run, world-steps/s

    def limit_now() -> float:
        """Worlds at 60 Hz that raw rollout holds right now (best of two short blocks)."""
        rate = max(rollout.block(block_s) for _ in range(2))
        blocks.append(rate)
        return rate / steps_per_world_s

    data: dict[str, Any] = {
        "rtf_goal": RTF_GOAL,
        "window_s": window,
        "target_share": TARGET_SHARE,
        "stream": "/v1/ws?worlds=0-(n-1)&rate=30[&format=binary], one subscriber",
    }
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    try:
        first = statistics.median([limit_now() for _ in range(2)])
        ctx.say(f"  limit now: raw rollout = {first:.0f} worlds at 60 Hz")
        runs = [("mujoco", "json"), ("mujoco", "binary"), ("warp", "json")]
        for engine, fmt in runs:
            errors: dict[str, str] = {}

            def measure(n: int, engine: str = engine, fmt: str = fmt, errors=errors) -> dict:
                before = limit_now()
                t0 = time.perf_counter()
                try:
                    env = {"ARMFLEET_ENGINE": engine}
                    with ctx.serve(n, "realtime", env=env) as server:
                        res = asyncio.run(
                            _measure_realtime(server, window, warmup, per_subscriber=n, fmt=fmt)
                        )
                except Exception as exc:
                    errors[str(n)] = f"{type(exc).__name__}: {exc}"
                    return {"nworld": n, "realtime_factor": None, "error": errors[str(n)]}
                after = limit_now()
                res["limit_worlds_beside"] = beside = (before + after) / 2
                res["share_of_limit_beside"] = n / beside
                ctx.say(
                    f"  {engine:>6} {fmt:>6} {n:>5} worlds  RTF {res['realtime_factor']:.3f}  "
                    f"= {n / beside:.2f}x the limit beside it ({beside:.0f}); engine "
                    f"{res.get('engine_share', 0):.3f} of the wall, loop "
                    f"{res.get('tick_share', 0) - res.get('engine_share', 0):.3f} "
                    f"({time.perf_counter() - t0:.1f} s)"
                )
                return res

            if engine == "mujoco":
                start = _round8(TARGET_SHARE * limit_now())
                best, candidates = ladder_search(measure, start, _round8(STEP * first), RESOLUTION)
            else:
                picked = list(ctx.worlds or [])
                start = picked[-1] if picked else 64
                best, candidates = capacity_search(measure, start, 4096, ctx.pick(2, 2))
            passed = [c for c in candidates if c.get("passed")]
            top = max(passed, key=lambda c: c["nworld"]) if passed else None
            key = engine if engine == "warp" or fmt == "json" else f"{engine}_{fmt}"
            data[key] = {
                "format": fmt,
                "capacity_worlds": best,
                "share_of_limit_beside": top["share_of_limit_beside"] if top else None,
                "candidates": candidates,
                "errors": errors,
            }
            rows += [
                {
                    "engine": engine,
                    "format": fmt,
                    "worlds": c["nworld"],
                    "RTF": c.get("realtime_factor"),
                    "limit beside": c.get("limit_worlds_beside"),
                    "worlds/limit": c.get("share_of_limit_beside"),
                    "engine share": c.get("engine_share"),
                    "ok": c.get("passed"),
                }
                for c in candidates
            ]
    finally:
        rollout.close()
    best_block = max(blocks)
    data["rollout_world_steps_per_s"] = best_block
    data["rollout_blocks"] = blocks
    data["limit_worlds"] = limit = best_block / steps_per_world_s
    data["limit_worlds_median"] = statistics.median(blocks) / steps_per_world_s
    for key in ("mujoco", "mujoco_binary", "warp"):
        e = data[key]
        best = e["capacity_worlds"]
        e["capacity_vs_limit"] = best / limit if best else None
        beside = e["share_of_limit_beside"]
        notes.append(
            f"{key}: {best or 'no'} worlds at RTF >= {RTF_GOAL} = "
            + (
                f"{best / limit:.2f}x the best limit of the run ({limit:.0f} worlds), "
                f"{beside:.2f}x the limit measured beside it"
                if best
                else "none passed"
            )
        )
    return Result(rows, data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
