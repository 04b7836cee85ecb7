"""Section 5: HTTP increments per second and their latency, 1 and 8 keep-alive clients.

Each client is a thread with its own ``httpx.Client`` (one keep-alive connection) posting
``POST /v1/worlds/{w}/increments`` with ``wrist_3_joint`` ±0.1 alternating, back to back, for a
fixed time; client i commands world i mod nworld. Latency is per request, send to reply.

Standalone: ``python -m bench.http_bench --worlds 16 --duration 10``.
"""

from __future__ import annotations

import argparse
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import httpx

from bench import common

SECTION = "http"
JOINT = "wrist_3_joint"
CLIENTS = (1, 8)


def defaults(quick: bool) -> dict[str, Any]:
    return {"worlds": 16, "duration": 3.0 if quick else 10.0, "warmup": 0.5 if quick else 1.0}


def _client(
    url: str,
    world: int,
    start: threading.Event,
    stop: threading.Event,
    lat: list[float],
    status: dict[int, int],
    errors: list[str],
) -> None:
    path = f"{url}/v1/worlds/{world}/increments"
    sign = 1.0
    with httpx.Client(timeout=30) as client:
        # One request before the clock starts opens the keep-alive connection.
        client.post(path, json={"joint": JOINT, "delta": 0.0})
        start.wait()
        while not stop.is_set():
            t0 = time.perf_counter()
            try:
                r = client.post(path, json={"joint": JOINT, "delta": sign * 0.1})
            except httpx.HTTPError as exc:
                errors.append(f"{type(exc).__name__}: {exc}")
                continue
            dt = time.perf_counter() - t0
            sign = -sign
            if not stop.is_set():  # a request that finished after the window is not counted
                lat.append(dt)
                status[r.status_code] = status.get(r.status_code, 0) + 1


def measure(server: common.Server, clients: int, duration: float, warmup: float) -> dict:
    """`clients` threads posting increments for `duration` s (after `warmup` s unmeasured)."""
    lats: list[list[float]] = [[] for _ in range(clients)]
    statuses: list[dict[int, int]] = [{} for _ in range(clients)]
    errors: list[str] = []
    start, stop = threading.Event(), threading.Event()
    threads = [
        threading.Thread(
            target=_client,
            args=(server.url, i % server.nworld, start, stop, lats[i], statuses[i], errors),
            daemon=True,
        )
        for i in range(clients)
    ]
    for t in threads:
        t.start()
    start.set()
    time.sleep(warmup)
    for lat in lats:
        lat.clear()
    for s in statuses:
        s.clear()
    t0 = time.perf_counter()
    time.sleep(duration)
    stop.set()
    wall = time.perf_counter() - t0
    for t in threads:
        t.join(timeout=30)
    every = [x for lat in lats for x in lat]
    status: dict[str, int] = {}
    for s in statuses:
        for code, k in s.items():
            status[str(code)] = status.get(str(code), 0) + k
    return {
        "clients": clients,
        "requests": len(every),
        "wall_s": wall,
        "requests_per_s": len(every) / wall,
        "latency": common.summary_ms(every),
        "status": status,
        "errors": errors[:10],
        "nerrors": len(errors),
    }


_WRK_SCRIPT = """
wrk.method = "POST"
wrk.headers["Content-Type"] = "application/json"
local n = 0
request = function()
  n = n + 1
  local delta = (n % 2 == 0) and 0.1 or -0.1
  return wrk.format(nil, nil, nil, '{"joint": "JOINT", "delta": ' .. delta .. '}')
end
done = function(summary, latency, requests)
  io.write(string.format("WRK %d %d %d %d %f %f %d\\n", summary.requests,
    summary.errors.status, summary.errors.connect + summary.errors.read + summary.errors.write,
    summary.errors.timeout, latency:percentile(50) / 1000, latency:percentile(99) / 1000,
    summary.duration))
end
"""


def measure_wrk(server: common.Server, connections: int, duration: float) -> dict | None:
    """The same request from wrk (a C load generator), so the client is not what is measured."""
    import shutil
    import subprocess
    import tempfile

    if shutil.which("wrk") is None:
        return None
    with tempfile.NamedTemporaryFile("w", suffix=".lua", delete=False) as f:
        f.write(_WRK_SCRIPT.replace("JOINT", JOINT))
    url = f"{server.url}/v1/worlds/0/increments"
    cmd = ["wrk", "-t1", f"-c{connections}", f"-d{max(1, round(duration))}s", "-s", f.name, url]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=duration + 30).stdout
    line = next(x for x in out.splitlines() if x.startswith("WRK "))
    req, non2xx, sock_err, timeouts, p50, p99, dur_us = line.split()[1:]
    return {
        "client": "wrk",
        "requests_per_s": int(req) / (int(dur_us) / 1e6),
        "latency": {"p50_ms": round(float(p50), 3), "p99_ms": round(float(p99), 3)},
        "non_2xx": int(non2xx),
        "errors": int(sock_err) + int(timeouts),
    }


def run(
    nworld: int = 16,
    duration: float = 10.0,
    warmup: float = 1.0,
    clients: Sequence[int] = CLIENTS,
    device: str = "cpu",
    server: common.Server | None = None,
    progress: Callable[[str], None] | None = print,
) -> dict[str, Any]:
    """Section 5 against `server` (realtime), or a realtime server of `nworld` started here."""
    started = common.now_iso()
    say = progress or (lambda _msg: None)
    results: dict[str, Any] = {}
    rtf: dict[str, float] = {}

    def go(srv: common.Server) -> None:
        t_info0, info0 = srv.get_info()
        for k in clients:
            res = measure(srv, k, duration, warmup)
            results[str(k)] = res
            say(
                f"  {k} client(s)  {res['requests_per_s']:,.0f} increments/s, "
                f"p50 {res['latency']['p50_ms']} ms, p99 {res['latency']['p99_ms']} ms"
            )
            fast = measure_wrk(srv, k, duration)
            if fast is not None:
                results[f"wrk/{k}"] = fast
                say(
                    f"  wrk, {k} connection(s)  {fast['requests_per_s']:,.0f} increments/s, "
                    f"p50 {fast['latency']['p50_ms']} ms, p99 {fast['latency']['p99_ms']} ms"
                )
        t_info1, info1 = srv.get_info()
        rtf["value"] = common.rtf(
            info1["tick"] - info0["tick"], info1["control_hz"], t_info1 - t_info0
        )

    if server is not None:
        go(server)
        nworld = server.nworld
    else:
        with common.running_server(nworld, "realtime", device) as srv:
            go(srv)
    data = {
        "device": device,
        "mode": "realtime",
        "nworld": nworld,
        "request": f"POST /v1/worlds/{{w}}/increments {{joint: {JOINT}, delta: ±0.1}}",
        "duration_s": duration,
        "warmup_s": warmup,
        "realtime_factor": common.finite(rtf.get("value")),
        "results": results,
    }
    return common.section_payload(SECTION, device, data, started)


def table(payload: dict[str, Any]):
    from rich import box
    from rich.table import Table

    rtf = payload.get("realtime_factor")
    t = Table(
        title=(
            f"5. HTTP increments, {payload['nworld']} worlds realtime "
            f"(RTF {'-' if rtf is None else f'{rtf:.2f}'} meanwhile; {payload['device']})"
        ),
        box=box.SIMPLE_HEAD,
    )
    for col in ("clients", "increments/s", "p50 ms", "p99 ms", "max ms", "non-200", "errors"):
        t.add_column(col, justify="right")
    for k, r in payload["results"].items():
        lat = r["latency"]
        if r.get("client") == "wrk":
            bad, errors = r["non_2xx"], r["errors"]
        else:
            bad = sum(v for code, v in r["status"].items() if code != "200")
            errors = r["nerrors"]
        t.add_row(
            k if "/" in k else f"httpx/{k}",
            f"{r['requests_per_s']:,.0f}",
            f"{lat['p50_ms']}",
            f"{lat['p99_ms']}",
            f"{lat.get('max_ms', '-')}",
            str(bad),
            str(errors),
        )
    return t


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.http_bench", description=__doc__)
    p.add_argument("--worlds", type=int, help="worlds in the server (default 16)")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--duration", type=float, help="seconds measured per client count")
    p.add_argument("--clients", type=int, nargs="+", default=list(CLIENTS))
    p.add_argument("--device", default="cpu")
    args = p.parse_args(argv)
    d = defaults(args.quick)
    payload = run(
        args.worlds or d["worlds"],
        args.duration or d["duration"],
        d["warmup"],
        args.clients,
        args.device,
    )
    path = common.write_json(f"{SECTION}{common.suffix_for(args.device)}.json", payload)
    common.console().print(table(payload))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
