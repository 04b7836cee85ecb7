"""Section 13: where MuJoCo Warp's CPU tick goes.

The uncaptured tick with every ``wp.launch`` timed (CPU launches are synchronous), each
kernel's median over the ticks, the top kernels at 64 and 1024 worlds: what to make faster
first, and how much of a tick is launch overhead that the service's captured tick removes.

Standalone: ``python -m bench.kernels --worlds 64``.
"""

from __future__ import annotations

import collections
import time
from typing import Any

from bench.registry import Context, Result, section


def _kernel_profile(nworld: int, ticks: int) -> dict[str, Any]:
    """Time every wp.launch of `ticks` uncaptured ticks (CPU launches run to completion).

    Each kernel's figure is its median over the ticks, so that a tick in which another process
    took the core does not count (the machine may be shared).
    """
    import statistics

    import warp as wp

    from service.engines.warp import WorldBatch

    batch = WorldBatch(nworld, capture=False)
    batch.step(2)
    per_tick: list[dict[str, float]] = []
    calls: collections.Counter[str] = collections.Counter()
    launch = wp.launch

    def timed(kernel: Any, *args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return launch(kernel, *args, **kwargs)
        finally:
            name = getattr(kernel, "key", str(kernel)).replace("__locals__", ".")
            per_tick[-1][name] = per_tick[-1].get(name, 0.0) + time.perf_counter() - t0
            calls[name] += 1

    walls = []
    wp.launch = timed  # mujoco_warp launches through the `wp` module's attribute
    try:
        for _ in range(ticks):
            per_tick.append({})
            t0 = time.perf_counter()
            batch.step(1)
            walls.append(time.perf_counter() - t0)
    finally:
        wp.launch = launch
    names = set().union(*per_tick)
    spent = {k: statistics.median(t.get(k, 0.0) for t in per_tick) for k in names}
    total = sum(spent.values())
    top = sorted(spent.items(), key=lambda kv: -kv[1])
    return {
        "nworld": nworld,
        "ticks": ticks,
        "ms_per_tick_uncaptured": statistics.median(walls) * 1e3,
        "ms_per_tick_in_launches": total * 1e3,
        "launches_per_tick": sum(calls.values()) / ticks,
        "kernels": [
            {
                "kernel": k,
                "ms_per_tick": v * 1e3,
                "share": v / total,
                "launches_per_tick": calls[k] / ticks,
            }
            for k, v in top
        ],
    }


@section(13, "kernels")
def kernels(ctx: Context) -> Result:
    """MuJoCo Warp CPU tick: top kernels (uncaptured, each launch timed)

    The uncaptured warp tick at 64 and 1024 worlds, every launch timed; the top ten each."""
    sizes = ctx.sizes((64, 1024), (64,))
    ticks = ctx.pick(15, 5)
    results, errors = ctx.each(
        sizes,
        lambda n: _kernel_profile(n, ticks),
        lambda r: f"{r['ms_per_tick_uncaptured']:.1f} ms/tick, top {r['kernels'][0]['kernel']}",
    )
    rows = [
        {
            "worlds": int(n),
            "kernel": k["kernel"][:48],
            "ms/tick": k["ms_per_tick"],
            "share": k["share"],
            "launches/tick": k["launches_per_tick"],
        }
        for n, r in results.items()
        for k in r["kernels"][:10]
    ]
    note = (
        "launch overhead (~tens of µs each, ~190 launches a tick) is inside each figure; the "
        "service replays a captured tick, which removes it"
    )
    return Result.per_size(rows, results, errors, notes=[note])


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
