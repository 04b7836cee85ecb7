"""Section 6: cold and warm start, process start → first ``/readyz`` 200.

* cold: Warp's kernel cache is an empty temporary directory (``WARP_CACHE_PATH``, which Warp 1.19
  reads at ``wp.init()`` and uses as ``<path>/<warp version>``), so every kernel the tick uses is
  generated and compiled;
* native: ``--engine mujoco``, which compiles nothing (median of the same number of starts);
* warm: the default cache (``wp.config.kernel_cache_dir``, ~/.cache/warp/<version> on Linux),
  after the cold run or any earlier use has filled it; the median of 3 starts (1 with
  ``--quick``).

Both include the Python interpreter's start and imports, building the worlds and capturing the
tick: it is the time clients.testing.serve takes to return, so its /readyz polling interval
(0.2 s) is the resolution.

Standalone: ``python -m bench.startup --quick``.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from typing import Any

from bench.registry import Context, Result, section


@section(6, "startup")
def startup(ctx: Context) -> Result:
    """Start → /readyz

    One start with an empty kernel cache, then `repeats` with the default one."""
    nworld = ctx.sizes((16,))[0]
    repeats = ctx.pick(3, 1)
    out: dict[str, Any] = {}
    errors: dict[str, str] = {}

    def start(label: str, env: dict[str, str] | None = None) -> float | None:
        t0 = time.perf_counter()
        try:
            with ctx.serve(nworld, "realtime", env) as server:
                ctx.say(f"  {label}: {server.ready_s:.1f} s")
                return server.ready_s
        except Exception as exc:
            errors[label] = f"{type(exc).__name__}: {exc}"
            ctx.say(f"  {label} FAILED after {time.perf_counter() - t0:.0f} s: {exc}")
            return None

    with tempfile.TemporaryDirectory(prefix="armfleet-warp-cache-") as cache:
        cold = start("cold", {"WARP_CACHE_PATH": cache})
    if cold is not None:
        out["cold"] = {"ready_s": cold}
    warm = [t for i in range(repeats) if (t := start(f"warm{i}")) is not None]
    if warm:
        out["warm"] = {
            "ready_s": statistics.median(warm),
            "runs_s": warm,
            "min_s": min(warm),
            "max_s": max(warm),
        }
    # The native engine (--engine mujoco) compiles nothing: its start is imports and the build.
    native = [
        t
        for i in range(repeats)
        if (t := start(f"native{i}", {"ARMFLEET_ENGINE": "mujoco"})) is not None
    ]
    if native:
        out["native"] = {"ready_s": statistics.median(native), "runs_s": native}
    data = {
        "nworld": nworld,
        "measured": "start of clients.testing.serve(`python -m service.cli serve`) → it returned "
        "after the first GET /readyz 200",
        "cold_cache": "WARP_CACHE_PATH=<empty temporary directory>",
        "warm_cache": "the default Warp kernel cache",
        "results": out,
        "errors": errors,
    }
    rows = []
    if cold is not None:
        rows.append({"kernel cache": "cold (empty)", "seconds": cold, "runs": 1})
    if warm:
        runs = ", ".join(f"{x:.1f}" for x in warm)
        rows.append(
            {"kernel cache": "warm (median)", "seconds": out["warm"]["ready_s"], "runs": runs}
        )
    if native:
        runs = ", ".join(f"{x:.1f}" for x in native)
        rows.append(
            {
                "kernel cache": "native engine (median)",
                "seconds": out["native"]["ready_s"],
                "runs": runs,
            }
        )
    return Result(rows, data, [f"{nworld} worlds"])


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
