"""Section 25: the service over its engine, alternating runs over the same simulated window.

Why: section 7 divides the service's world-steps/s (a window after the worlds settled) by
section 1's engine (a short window right after ``SETTLE_TICKS``), taken minutes apart and over
different ticks, and a tick's cost changes as the worlds settle. At 16,384 worlds on an H200
the ratio came out 0.94-0.96 with 3 s windows: too close to issue 39's 0.95 to tell. Here a
pair is one service run (``armfleet serve --mode fast``, every world streamed at 30 Hz in binary
frames to one client, exactly section 7's measurement) and then the engine (``WorldBatch.step``
in this process, built once a size, reset to home each time) timed over exactly the ticks the
service's window covered, the ticks before it run untimed. Pairs follow each other (service,
engine, service, engine, ...), so both meet the same moments of the machine; the ratio of every
pair, and of the medians.

Standalone: ``python -m bench.service_vs_engine --section 25 --device cuda --worlds 16384``.
"""

from __future__ import annotations

import asyncio
import gc
import statistics
import time
from typing import Any

import numpy as np

from bench import common
from bench.registry import Context, Result, section
from bench.service_probe import measure_fast


def engine_over(batch: Any, first: int, last: int) -> dict[str, Any]:
    """The engine from home: ticks [0, first) untimed, then [first, last) timed."""
    batch.reset(np.arange(batch.nworld))
    batch.step(first)
    t0 = time.perf_counter()
    for _ in range(last - first):
        batch.step(1)  # reads the fault count: each tick is timed to completion
    wall = time.perf_counter() - t0
    ticks = last - first
    return {
        "ticks": ticks,
        "wall_s": wall,
        "world_steps_per_s": common.world_steps(ticks, batch.nworld, batch.substeps) / wall,
    }


def pairs_at(ctx: Context, n: int, pairs: int, duration: float, warmup: float) -> dict[str, Any]:
    from service.engines.warp import WorldBatch

    batch = WorldBatch(n, device=ctx.device)
    runs = []
    try:
        for i in range(pairs):
            with ctx.serve(n, "fast") as server:
                svc = asyncio.run(measure_fast(server, duration, warmup, "binary"))
            first, last = svc["tick_last"] - svc["ticks"], svc["tick_last"]
            eng = engine_over(batch, first, last)
            ratio = svc["world_steps_per_s"] / eng["world_steps_per_s"]
            runs.append({"service": svc, "engine": eng, "ratio": ratio})
            ctx.say(
                f"  {n:>6} worlds  pair {i + 1}: service {svc['world_steps_per_s']:,.0f}, engine "
                f"{eng['world_steps_per_s']:,.0f} over ticks {first}-{last}: {ratio:.3f}"
            )
    finally:
        del batch
        gc.collect()
    svc_med = statistics.median(r["service"]["world_steps_per_s"] for r in runs)
    eng_med = statistics.median(r["engine"]["world_steps_per_s"] for r in runs)
    return {
        "runs": runs,
        "ratios": [r["ratio"] for r in runs],
        "service_median": svc_med,
        "engine_median": eng_med,
        "ratio_of_medians": svc_med / eng_med,
        "frames_per_s": [r["service"]["frames_per_s"] for r in runs],
    }


@section(25, "service_vs_engine", ("cpu", "cuda"), default_on=())
def service_vs_engine(ctx: Context) -> Result:
    """Service over engine, fast mode, binary frames: alternating runs over the same ticks"""
    sizes = ctx.sizes(
        (16384, 65536) if ctx.cuda else (256, 1024), quick=(16384,) if ctx.cuda else (64,)
    )
    pairs, duration, warmup = ctx.pick((3, 10.0, 2.0), (1, 3.0, 1.0))
    results, errors = ctx.each(
        sizes,
        lambda n: pairs_at(ctx, n, pairs, duration, warmup),
        lambda r: f"ratios {', '.join(f'{x:.3f}' for x in r['ratios'])}",
    )
    rows = [
        {
            "worlds": int(n),
            "service, median world-steps/s": r["service_median"],
            "engine, median world-steps/s": r["engine_median"],
            "svc/engine (medians)": r["ratio_of_medians"],
            "svc/engine, each pair": " ".join(f"{x:.3f}" for x in r["ratios"]),
            "frames/s": statistics.median(r["frames_per_s"]),
        }
        for n, r in results.items()
    ]
    return Result.per_size(
        rows,
        results,
        errors,
        {
            "stream": "/v1/ws?rate=30&format=binary (all worlds, one client)",
            "pairs": pairs,
            "duration_s": duration,
            "warmup_s": warmup,
        },
    )


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
