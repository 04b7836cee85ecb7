"""Section 19: this tree's served speed against another revision's, in one run.

``ARMFLEET_BENCH_AGAINST=<git revision> armfleet bench --section 19`` checks that revision out
into a temporary worktree and serves the same batch from both trees side by side, one engine at
a time, as section 10 serves it (``--mode fast``, every world streamed at 30 Hz as JSON to one
client). Both servers stay up; in each round one is paused while the other runs a window in fast
mode, and the order alternates round by round, so the two share whatever the machine is doing.
The ratio is this tree's world-steps/s over the other's (best window of each, and medians): a
change to the command path must not cost ticks.

Standalone: ``ARMFLEET_BENCH_AGAINST=1b34e76 python -m bench.code_vs --section 19 --worlds 1024``.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import statistics
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from bench import common
from bench.registry import Context, Result, section

ROOT = Path(__file__).resolve().parents[1]
ENGINES = ("mujoco", "warp")


@contextlib.contextmanager
def checkout(rev: str) -> Iterator[Path]:
    """A detached worktree of `rev`, removed afterwards."""
    folder = Path(tempfile.mkdtemp(prefix="armfleet-against-"))
    subprocess.run(
        ["git", "worktree", "add", "--detach", str(folder), rev],
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    try:
        yield folder
    finally:
        subprocess.run(
            ["git", "worktree", "remove", "--force", str(folder)], cwd=ROOT, capture_output=True
        )


async def _window(client: Any, window: float) -> float:
    """One fast-mode window of a paused server: world-steps/s; paused again afterwards."""
    from bench.service_probe import timed_info

    (await client.post("/v1/sim/mode", json={"mode": "fast"})).raise_for_status()
    await asyncio.sleep(0.5)
    t0, info0 = await timed_info(client, str(client.base_url))
    await asyncio.sleep(window)
    t1, info1 = await timed_info(client, str(client.base_url))
    (await client.post("/v1/sim/pause")).raise_for_status()
    ticks = info1["tick"] - info0["tick"]
    return common.world_steps(ticks, info1["nworld"], info1["substeps"]) / (t1 - t0)


async def _alternate(servers: dict[str, common.Served], rounds: int, window: float) -> dict:
    """Rounds of one window per server, the order alternating; each streamed to one client."""
    import httpx

    from bench.service_probe import FrameCounter

    readers = []
    for srv in servers.values():
        counter = FrameCounter()
        readers.append(asyncio.create_task(counter.run(f"{srv.ws_url}/v1/ws?rate=30&format=json")))
    samples: dict[str, list[float]] = {name: [] for name in servers}
    try:
        clients = {n: httpx.AsyncClient(base_url=s.url, timeout=60) for n, s in servers.items()}
        for client in clients.values():
            (await client.post("/v1/sim/pause")).raise_for_status()
        names = list(servers)
        for r in range(rounds):
            for name in names if r % 2 == 0 else names[::-1]:
                samples[name].append(await _window(clients[name], window))
        for client in clients.values():
            await client.aclose()
    finally:
        for reader in readers:
            reader.cancel()
        await asyncio.gather(*readers, return_exceptions=True)
    return samples


@section(19, "code_vs", default_on=())
def code_vs(ctx: Context) -> Result:
    """This tree vs another revision, served fast mode, one run"""
    rev = os.environ.get("ARMFLEET_BENCH_AGAINST")
    if not rev:
        return Result([], {"errors": {"setup": "set ARMFLEET_BENCH_AGAINST=<git revision>"}})
    sizes = ctx.sizes((1024,), (1024,))
    rounds, window = ctx.pick((6, 3.0), (4, 2.0))
    here = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True, capture_output=True
    ).stdout.strip()
    results: dict[str, Any] = {}
    errors: dict[str, str] = {}
    with checkout(rev) as other:
        for n in sizes:
            for engine in ENGINES:
                key = f"{n}/{engine}"
                t0 = time.perf_counter()
                try:
                    env = {"ARMFLEET_ENGINE": engine}
                    with (
                        common.served(n, "fast", ctx.device, env, cwd=ROOT) as this,
                        common.served(n, "fast", ctx.device, env, cwd=other) as that,
                    ):
                        samples = asyncio.run(
                            _alternate({"this": this, "other": that}, rounds, window)
                        )
                except Exception as exc:  # one failure loses one row
                    errors[key] = f"{type(exc).__name__}: {exc}"
                    continue
                best = {k: max(v) for k, v in samples.items()}
                median = {k: statistics.median(v) for k, v in samples.items()}
                results[key] = {
                    "nworld": n,
                    "engine": engine,
                    "windows": samples,
                    "best": best,
                    "median": median,
                    "ratio_best": best["this"] / best["other"],
                    "ratio_median": median["this"] / median["other"],
                }
                ctx.say(
                    f"  {key}: this {best['this']:,.0f} vs {rev} {best['other']:,.0f} world-steps/s"
                    f" ({results[key]['ratio_best']:.3f}x best, "
                    f"{results[key]['ratio_median']:.3f}x median; "
                    f"{time.perf_counter() - t0:.0f} s)"
                )
    rows = [
        {
            "worlds": r["nworld"],
            "engine": r["engine"],
            f"this ({here})": r["best"]["this"],
            f"against ({rev})": r["best"]["other"],
            "this/against best": r["ratio_best"],
            "this/against median": r["ratio_median"],
        }
        for r in results.values()
    ]
    data = {
        "against": rev,
        "this": here,
        "mode": "fast",
        "stream": "/v1/ws?rate=30&format=json (all worlds, one client per server)",
        "rounds": rounds,
        "window_s": window,
        "results": results,
        "errors": errors,
    }
    notes = ["both trees served at once, one paused while the other runs; order alternates"]
    return Result(rows, data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
