"""Section 6: cold and warm start, process start → first ``/readyz`` 200.

* cold: Warp's kernel cache is an empty temporary directory (``WARP_CACHE_PATH``, which Warp 1.19
  reads at ``wp.init()`` and uses as ``<path>/<warp version>``), so every kernel the tick uses is
  generated and compiled;
* warm: the default cache (``wp.config.kernel_cache_dir``, ~/.cache/warp/<version> on Linux),
  after the cold run or any earlier use has filled it; the median of `repeats` starts.

Both include the Python interpreter's start and imports, building the worlds and capturing the
tick. /readyz is polled every 50 ms.

Standalone: ``python -m bench.startup --worlds 16 --repeats 3``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from typing import Any

from bench import common

SECTION = "startup"


def defaults(quick: bool) -> dict[str, Any]:
    return {"worlds": 16, "repeats": 1 if quick else 3, "cold": True}


def start_once(nworld: int, device: str, env: dict[str, str] | None = None) -> dict[str, Any]:
    with common.running_server(nworld, "realtime", device, env=env) as server:
        return {"ready_s": server.ready_s, "captured": server.info.get("captured")}


def run(
    nworld: int = 16,
    repeats: int = 3,
    cold: bool = True,
    device: str = "cpu",
    progress: Callable[[str], None] | None = print,
) -> dict[str, Any]:
    started = common.now_iso()
    say = progress or (lambda _msg: None)
    out: dict[str, Any] = {}
    errors: dict[str, str] = {}
    if cold:
        with tempfile.TemporaryDirectory(prefix="armfleet-warp-cache-") as cache:
            t0 = time.perf_counter()
            try:
                out["cold"] = start_once(nworld, device, env={"WARP_CACHE_PATH": cache})
                say(f"  cold start (empty kernel cache): {out['cold']['ready_s']:.1f} s")
            except Exception as exc:
                errors["cold"] = f"{type(exc).__name__}: {exc}"
                say(f"  cold start FAILED after {time.perf_counter() - t0:.0f} s: {exc}")
    warm: list[float] = []
    for i in range(repeats):
        try:
            warm.append(start_once(nworld, device)["ready_s"])
            say(f"  warm start {i + 1}/{repeats}: {warm[-1]:.1f} s")
        except Exception as exc:
            errors[f"warm{i}"] = f"{type(exc).__name__}: {exc}"
            say(f"  warm start FAILED: {exc}")
    if warm:
        out["warm"] = {
            "ready_s": statistics.median(warm),
            "runs_s": warm,
            "min_s": min(warm),
            "max_s": max(warm),
        }
    data = {
        "device": device,
        "nworld": nworld,
        "measured": "Popen of `python -m service.cli serve` → first GET /readyz 200 (50 ms polls)",
        "cold_cache": "WARP_CACHE_PATH=<empty temporary directory>",
        "warm_cache": "the default Warp kernel cache",
        "results": out,
        "errors": errors,
    }
    return common.section_payload(SECTION, device, data, started)


def table(payload: dict[str, Any]):
    from rich import box
    from rich.table import Table

    t = Table(
        title=f"6. Start → /readyz, {payload['nworld']} worlds ({payload['device']})",
        box=box.SIMPLE_HEAD,
    )
    for col in ("kernel cache", "seconds", "runs"):
        t.add_column(col, justify="right")
    r = payload["results"]
    if "cold" in r:
        t.add_row("cold (empty)", f"{r['cold']['ready_s']:.1f}", "1")
    if "warm" in r:
        runs = ", ".join(f"{x:.1f}" for x in r["warm"]["runs_s"])
        t.add_row("warm (median)", f"{r['warm']['ready_s']:.1f}", runs)
    return t


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.startup", description=__doc__)
    p.add_argument("--worlds", type=int, default=16)
    p.add_argument("--repeats", type=int, help="warm starts (median reported)")
    p.add_argument("--quick", action="store_true", help="one warm start")
    p.add_argument("--no-cold", action="store_true", help="skip the cold-cache start")
    p.add_argument("--device", default="cpu")
    args = p.parse_args(argv)
    d = defaults(args.quick)
    payload = run(
        args.worlds,
        args.repeats or d["repeats"],
        not args.no_cold,
        args.device,
    )
    path = common.write_json(f"{SECTION}{common.suffix_for(args.device)}.json", payload)
    common.console().print(table(payload))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
