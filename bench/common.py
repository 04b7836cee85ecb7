"""Shared pieces of the benchmark sections: machine info, result files, timing, a served service.

Nothing here imports Warp at module level, so that the sections that only talk to a
server subprocess stay light on the (shared, 2-core) machine they measure.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import importlib.metadata
import json
import math
import os
import platform
import socket
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from service.core.sim.physics import DEFAULT_PHYSICS_DT
from service.engines.cores import usable_cores

RESULTS_DIR = Path(__file__).resolve().parent / "results"

# The simulation's defaults (service.core.sim.settings.SimSettings): 60 Hz control, the
# default physics step.
CONTROL_HZ = 60.0
PHYSICS_DT = DEFAULT_PHYSICS_DT
# The physics step before the step study of issue 13 (8 substeps of 2.083 ms per 60 Hz tick).
OLD_PHYSICS_DT = 0.002


# -- results ---------------------------------------------------------------------------------


def now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _version(dist: str) -> str | None:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return None


def cpu_model() -> str:
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def gpu_name(device: str) -> str | None:
    """The CUDA device's name, or None (imports Warp only for a cuda device)."""
    if not device.startswith("cuda"):
        return None
    with contextlib.suppress(Exception):
        import warp as wp

        return str(wp.get_device(device).name)
    return None


def machine_info(device: str = "cpu") -> dict[str, Any]:
    info: dict[str, Any] = {
        "cpu_model": cpu_model(),
        "cpu_count": os.cpu_count(),
        "usable_cores": usable_cores(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "mujoco": _version("mujoco"),
        "mujoco_warp": _version("mujoco-warp"),
        "warp": _version("warp-lang"),
        "numpy": _version("numpy"),
        "device": device,
        "gpu": gpu_name(device),
        "hostname": socket.gethostname(),
    }
    with contextlib.suppress(OSError):
        info["loadavg_at_start"] = [round(x, 2) for x in os.getloadavg()]
    return info


def suffix_for(device: str) -> str:
    """File name suffix: CPU results are the default files, GPU runs do not overwrite them."""
    return "" if device == "cpu" else "_" + device.replace(":", "")


def write_json(name: str, payload: Mapping[str, Any], results_dir: Path | None = None) -> Path:
    """Write `payload` as results_dir/name atomically (a .tmp then a rename)."""
    out_dir = results_dir or RESULTS_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / name
    tmp = path.with_suffix(path.suffix + ".tmp")
    text = json.dumps(_no_nan(payload), indent=2, default=_json_default, allow_nan=False)
    tmp.write_text(text + "\n")
    tmp.replace(path)
    return path


def _no_nan(obj: Any) -> Any:
    """NaN and infinities (not JSON) become null, at any depth."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {k: _no_nan(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_no_nan(v) for v in obj]
    return obj


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def read_json(name: str, results_dir: Path | None = None) -> dict[str, Any] | None:
    path = (results_dir or RESULTS_DIR) / name
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def finite(x: float | None) -> float | None:
    """JSON has no NaN/inf: such values become null."""
    if x is None or not math.isfinite(x):
        return None
    return float(x)


# -- statistics and timing -------------------------------------------------------------------


def percentile(values: Sequence[float], q: float) -> float | None:
    """Linear-interpolated percentile (q in 0..100) of `values`; None when empty."""
    if not values:
        return None
    xs = sorted(values)
    pos = (len(xs) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


def summary_ms(seconds: Sequence[float]) -> dict[str, Any]:
    """n, p50, p99, mean and max of durations given in seconds, reported in milliseconds."""
    if not seconds:
        return {"n": 0, "p50_ms": None, "p99_ms": None, "mean_ms": None, "max_ms": None}

    def ms(x: float | None) -> float | None:
        return None if x is None else round(x * 1e3, 3)

    return {
        "n": len(seconds),
        "p50_ms": ms(percentile(seconds, 50)),
        "p99_ms": ms(percentile(seconds, 99)),
        "mean_ms": ms(sum(seconds) / len(seconds)),
        "max_ms": ms(max(seconds)),
    }


@dataclass
class Timing:
    """`reps` calls of something that took `elapsed` seconds in all."""

    reps: int
    elapsed: float
    warmup: int = 0  # calls made before the timed ones

    @property
    def per_call(self) -> float:
        return self.elapsed / self.reps


def time_calls(
    fn: Callable[[], Any],
    min_time: float,
    warmup_time: float = 0.0,
    min_reps: int = 3,
    warmup_reps: int = 1,
    sync: Callable[[], Any] | None = None,
    max_reps: int = 1_000_000,
) -> Timing:
    """Call `fn` to warm up, then time it until >= `min_time` s and >= `min_reps` calls.

    `sync` (e.g. ``wp.synchronize_device``) runs before the clock is read, so asynchronous
    devices are timed to completion. The clock is read after every call, so one call may be
    long (a 4096-world tick) or short (one world) without another calibration pass.
    """
    t0 = time.perf_counter()
    n = 0
    while n < warmup_reps or time.perf_counter() - t0 < warmup_time:
        fn()
        n += 1
    if sync:
        sync()
    reps = 0
    t0 = time.perf_counter()
    elapsed = 0.0
    while reps < min_reps or (elapsed < min_time and reps < max_reps):
        fn()
        reps += 1
        if sync:
            sync()
        elapsed = time.perf_counter() - t0
    return Timing(reps, elapsed, n)


# -- the service as a subprocess (clients.testing.serve) ----------------------------------------


@dataclass
class Served:
    """A running `armfleet serve` (clients.testing's Server) with what the bench reads off it."""

    server: Any  # clients.testing.Server: url, ws_url, process, log()
    url: str  # http://127.0.0.1:<port>
    ws_url: str  # ws://127.0.0.1:<port>
    nworld: int
    ready_s: float  # entering serve() → it returned after the first /readyz 200
    info: dict[str, Any] = field(default_factory=dict)  # /v1/info at ready

    def get_info(self) -> tuple[float, dict[str, Any]]:
        """(perf_counter at the middle of the request, /v1/info)."""
        t0 = time.perf_counter()
        r = httpx.get(f"{self.url}/v1/info", timeout=30)
        t1 = time.perf_counter()
        r.raise_for_status()
        return (t0 + t1) / 2, r.json()


@contextlib.contextmanager
def served(
    nworld: int,
    mode: str,
    device: str,
    env: Mapping[str, str] | None = None,
    cwd: str | Path | None = None,
) -> Iterator[Served]:
    """`python -m service.cli serve` on `device` via clients.testing.serve (stopped with SIGINT);
    `cwd`: another source tree's root to serve that tree's code."""
    from clients.testing import serve

    args = ("--device", device, "--log-level", "warning")
    t0 = time.perf_counter()
    # A cold kernel cache compiles every kernel: minutes on a small CPU, more for CUDA.
    with serve(nworld, mode, extra_args=args, env=env, ready_timeout=900, cwd=cwd) as server:
        ready_s = time.perf_counter() - t0
        srv = Served(server, server.url, server.ws_url, nworld, ready_s)
        srv.info = srv.get_info()[1]
        yield srv


def world_steps(ticks: int, nworld: int, substeps: int) -> int:
    return ticks * nworld * substeps


def rtf(ticks: int, control_hz: float, wall_s: float) -> float:
    """Real-time factor: simulated seconds per wall second."""
    return (ticks / control_hz) / wall_s if wall_s > 0 else math.nan


def rtf_between(a: tuple[float, dict[str, Any]], b: tuple[float, dict[str, Any]]) -> float:
    """Real-time factor between two (time, /v1/info) readings."""
    return rtf(b[1]["tick"] - a[1]["tick"], b[1]["control_hz"], b[0] - a[0])


def cuda_available() -> bool:
    import warp as wp

    import service.engines.warp  # noqa: F401  (sets Warp's log level: no banner)

    try:
        return wp.is_cuda_available()
    except Exception:
        return False


# -- printing ----------------------------------------------------------------------------------


def si(x: float | None, digits: int = 3) -> str:
    """12345 → '12.3k', 2.5e6 → '2.50M'; None → '-'."""
    if x is None or not math.isfinite(x):
        return "-"
    for div, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if abs(x) >= div:
            return f"{x / div:.{digits}g}{unit}"
    return f"{x:.{digits}g}"


def cell(x: Any) -> str:
    """A table cell: None → '-', bools yes/no, floats with 3 significant digits (k, M, G)."""
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float):
        return si(x)
    return str(x)


def console():
    """A rich Console at least 120 columns wide, also when stdout is a pipe or a file."""
    from rich.console import Console

    c = Console()
    return c if c.is_terminal and c.width >= 120 else Console(width=max(120, c.width))


# -- figures as text (bench/figures.py and bench/readme_tables.py write them alike) -------------


def fmt_rate(x: float | None) -> str:
    """World-steps/s as 4.73M / 812k."""
    if x is None:
        return "–"
    return f"{x / 1e6:.2f}M" if x >= 1e6 else f"{x / 1e3:.0f}k"


def fmt_ratio(x: float | None) -> str:
    """A ratio as 1.02×."""
    return "–" if x is None else f"{x:.2f}×"


def md_table(head: list[str], rows: list[list[str]]) -> str:
    """A Markdown table, the first column left-aligned, numbers right."""
    align = ["---"] + ["---:"] * (len(head) - 1)
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)
