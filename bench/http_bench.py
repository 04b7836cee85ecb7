"""Section 5: HTTP increments per second and their latency, 1 and 8 keep-alive clients.

Each client is a thread with its own ``httpx.Client`` (one keep-alive connection) posting
``POST /v1/worlds/{w}/increments`` with ``wrist_3_joint`` ±0.1 alternating, back to back, for a
fixed time; client i commands world i mod nworld. Latency is per request, send to reply.

Standalone: ``python -m bench.http_bench --quick``.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import httpx

from bench import common
from bench.registry import Context, Result, section

JOINT = "wrist_3_joint"
CLIENTS = (1, 8)


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


def measure(server: common.Served, clients: int, duration: float, warmup: float) -> dict:
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


def measure_wrk(server: common.Served, connections: int, duration: float) -> dict | None:
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


def row(name: str, r: dict[str, Any]) -> dict[str, Any]:
    lat = r["latency"]
    if r.get("client") == "wrk":
        bad, errors = r["non_2xx"], r["errors"]
    else:
        bad = sum(v for code, v in r["status"].items() if code != "200")
        errors = r["nerrors"]
    return {
        "client": name if "/" in name else f"httpx/{name}",
        "increments/s": r["requests_per_s"],
        "p50 ms": lat["p50_ms"],
        "p99 ms": lat["p99_ms"],
        "max ms": lat.get("max_ms"),
        "non-200": bad,
        "errors": errors,
    }


@section(5, "http")
def http(ctx: Context) -> Result:
    """HTTP increments, realtime mode

    Python clients (threads with httpx), then wrk when installed, against one realtime server."""
    nworld = ctx.sizes((16,))[0]
    duration, warmup = ctx.pick((10.0, 1.0), (3.0, 0.5))
    results: dict[str, Any] = {}
    # Back to back on one connection is over the default command rate of a connection (429):
    # this section measures what HTTP carries, so the limit is lifted.
    with ctx.serve(nworld, "realtime", env={"ARMFLEET_COMMAND_RATE": "1000000"}) as server:
        before = server.get_info()
        for k in CLIENTS:
            results[str(k)] = res = measure(server, k, duration, warmup)
            ctx.say(
                f"  {k} client(s)  {res['requests_per_s']:,.0f} increments/s, "
                f"p50 {res['latency']['p50_ms']} ms, p99 {res['latency']['p99_ms']} ms"
            )
            fast = measure_wrk(server, k, duration)
            if fast is not None:
                results[f"wrk/{k}"] = fast
                ctx.say(
                    f"  wrk, {k} connection(s)  {fast['requests_per_s']:,.0f} increments/s, "
                    f"p50 {fast['latency']['p50_ms']} ms, p99 {fast['latency']['p99_ms']} ms"
                )
        rtf = common.rtf_between(before, server.get_info())
    data = {
        "mode": "realtime",
        "nworld": nworld,
        "request": f"POST /v1/worlds/{{w}}/increments {{joint: {JOINT}, delta: ±0.1}}",
        "duration_s": duration,
        "warmup_s": warmup,
        "realtime_factor": common.finite(rtf),
        "results": results,
    }
    notes = [f"{nworld} worlds; the loop ran at RTF {common.cell(data['realtime_factor'])}"]
    if not any(k.startswith("wrk/") for k in results):
        notes.append("wrk is not installed: Python clients only")
    return Result([row(k, r) for k, r in results.items()], data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
