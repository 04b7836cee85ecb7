"""Shared pieces of the benchmark sections: machine info, result files, timing, a server process.

Nothing here imports Warp or MuJoCo at module level, so that the sections that only talk to a
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
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from service.physics import DEFAULT_PHYSICS_DT

ROOT = Path(__file__).resolve().parents[1]
RESULTS_DIR = Path(__file__).resolve().parent / "results"

# The engine's defaults (service.settings.Settings): 60 Hz control, the default physics step.
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


def usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


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


def section_payload(section: str, device: str, data: Mapping[str, Any], started: str) -> dict:
    """The envelope every section file shares: what ran, where, when."""
    return {
        "section": section,
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]],
        "started": started,
        "finished": now_iso(),
        "machine": machine_info(device),
        **data,
    }


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
    return Timing(reps, elapsed)


# -- the service as a subprocess ---------------------------------------------------------------


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServerError(RuntimeError):
    pass


@dataclass
class Server:
    """A running `armfleet serve` subprocess."""

    url: str
    ws_url: str
    process: subprocess.Popen[bytes]
    log_path: Path
    nworld: int
    mode: str
    device: str
    started: float  # perf_counter at Popen
    ready_s: float = math.nan  # Popen → first /readyz 200
    info: dict[str, Any] = field(default_factory=dict)  # /v1/info at ready

    def log_tail(self, nchars: int = 4000) -> str:
        with contextlib.suppress(OSError):
            return self.log_path.read_text(errors="replace")[-nchars:]
        return ""

    def get_info(self, client: httpx.Client | None = None) -> tuple[float, dict[str, Any]]:
        """(perf_counter at the middle of the request, /v1/info)."""
        t0 = time.perf_counter()
        if client is None:
            r = httpx.get(f"{self.url}/v1/info", timeout=30)
        else:
            r = client.get(f"{self.url}/v1/info", timeout=30)
        t1 = time.perf_counter()
        r.raise_for_status()
        return (t0 + t1) / 2, r.json()


def server_command(
    nworld: int, mode: str, port: int, device: str = "cpu", extra: Sequence[str] = ()
) -> list[str]:
    return [
        sys.executable,
        "-m",
        "service.cli",
        "serve",
        "--worlds",
        str(nworld),
        "--mode",
        mode,
        "--port",
        str(port),
        "--device",
        device,
        "--log-level",
        "warning",
        *extra,
    ]


@contextlib.contextmanager
def running_server(
    nworld: int,
    mode: str = "realtime",
    device: str = "cpu",
    env: Mapping[str, str] | None = None,
    ready_timeout: float = 900.0,
    poll: float = 0.05,
    log_dir: Path | None = None,
) -> Iterator[Server]:
    """Start `python -m service.cli serve`, wait for /readyz 200, stop it (SIGINT) afterwards.

    `ready_s` is the wall time from Popen to the first 200, polled every `poll` seconds.
    """
    port = free_port()
    tmp = None
    if log_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="armfleet-bench-")
        log_dir = Path(tmp.name)
    log_path = log_dir / f"server-{nworld}-{mode}-{port}.log"
    proc_env = {**os.environ, **(env or {})}
    with open(log_path, "wb") as log:
        started = time.perf_counter()
        proc = subprocess.Popen(
            server_command(nworld, mode, port, device),
            cwd=ROOT,
            stdout=log,
            stderr=subprocess.STDOUT,
            env=proc_env,
        )
    url = f"http://127.0.0.1:{port}"
    server = Server(
        url=url,
        ws_url=f"ws://127.0.0.1:{port}",
        process=proc,
        log_path=log_path,
        nworld=nworld,
        mode=mode,
        device=device,
        started=started,
    )
    try:
        deadline = started + ready_timeout
        with httpx.Client(timeout=2.0) as client:
            while True:
                if proc.poll() is not None:
                    raise ServerError(f"server exited with {proc.returncode}:\n{server.log_tail()}")
                with contextlib.suppress(httpx.HTTPError):
                    if client.get(f"{url}/readyz").status_code == 200:
                        server.ready_s = time.perf_counter() - started
                        break
                if time.perf_counter() > deadline:
                    raise ServerError(f"server not ready in {ready_timeout:.0f} s")
                time.sleep(poll)
            server.info = client.get(f"{url}/v1/info").json()
        yield server
    finally:
        stop_server(proc)
        if tmp is not None:
            tmp.cleanup()


def stop_server(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.send_signal(2)  # SIGINT, like Ctrl-C: uvicorn shuts down gracefully
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def world_steps(ticks: int, nworld: int, substeps: int) -> int:
    return ticks * nworld * substeps


def rtf(ticks: int, control_hz: float, wall_s: float) -> float:
    """Real-time factor: simulated seconds per wall second."""
    return (ticks / control_hz) / wall_s if wall_s > 0 else math.nan


# -- printing ----------------------------------------------------------------------------------


def si(x: float | None, digits: int = 3) -> str:
    """12345 → '12.3k', 2.5e6 → '2.50M'; None → '-'."""
    if x is None or not math.isfinite(x):
        return "-"
    for div, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if abs(x) >= div:
            return f"{x / div:.{digits}g}{unit}"
    return f"{x:.{digits}g}"


def ratio(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.2f}x"


def console():
    """A rich Console at least 120 columns wide, also when stdout is a pipe or a file."""
    from rich.console import Console

    c = Console()
    return c if c.is_terminal and c.width >= 120 else Console(width=max(120, c.width))
