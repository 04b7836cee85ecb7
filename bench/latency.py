"""Section 4: command latency over the WebSocket, in realtime mode.

A controller on ``/v1/ws/worlds/{w}?rate=60`` (a frame every tick) sends ``increment`` on
``wrist_3_joint``, alternating +0.1 / -0.1 so the arm stays in range, and measures from the send:

* ``ack``: the ack reply;
* ``target``: the first state frame with ``tick >= ack.tick`` whose target equals the ack's;
* ``moved``: the first state frame where the joint has moved >= 0.01 rad in the commanded
  direction from where the last frame before the send had it.

Then it sends the next one. `controllers` sockets (on worlds 0..k-1; 4, or 8 from 64 worlds up,
where ticks are slow) run side by side to collect the samples sooner; the count is in the JSON.

Standalone: ``python -m bench.latency --worlds 16 256 --commands 1000``.
"""

from __future__ import annotations

import argparse
import asyncio
import time
from collections.abc import Callable, Sequence
from typing import Any

import orjson
import websockets.asyncio.client as ws_client

from bench import common

SECTION = "latency"
SIZES = (16, 64, 256)  # the latency target is stated at 64 worlds
JOINT = "wrist_3_joint"
JOINT_INDEX = 5  # position in the frames' name list (service.robot.JOINT_NAMES)
DELTA = 0.1
MOVED = 0.01
COMMAND_TIMEOUT = 10.0
RATE = 60.0  # frames/s each controller asks for: every tick of the 60 Hz loop


def controllers_for(nworld: int) -> int:
    """Sockets commanding side by side: more where ticks are slow, so samples come in sooner."""
    return 4 if nworld < 64 else 8


def defaults(quick: bool) -> dict[str, Any]:
    return {"sizes": SIZES, "commands": 100 if quick else 1000, "controllers": None}


async def _controller(
    url: str, ncommands: int, out: dict[str, list[float]], deadline: float
) -> dict[str, int]:
    counts = {"sent": 0, "timeouts": 0, "errors": 0}
    async with ws_client.connect(url, max_size=None, compression=None) as ws:
        last: dict[str, Any] | None = None
        while last is None:  # the current state comes at once on connect
            msg = orjson.loads(await ws.recv())
            if msg.get("op") == "state":
                last = msg
        joint = last["name"].index(JOINT)
        sign = 1.0 if last["target"][joint] < 0 else -1.0  # first step towards zero
        for i in range(ncommands):
            if time.perf_counter() > deadline:
                break
            pos0 = last["position"][joint]
            delta = sign * DELTA
            sign = -sign
            t_send = time.perf_counter()
            msg = {"op": "increment", "joint": JOINT, "delta": delta, "id": i}
            await ws.send(orjson.dumps(msg).decode())  # text: the service reads text frames
            counts["sent"] += 1
            ack: dict[str, Any] | None = None
            t_target = t_moved = None
            try:
                async with asyncio.timeout(COMMAND_TIMEOUT):
                    while t_target is None or t_moved is None:
                        msg = orjson.loads(await ws.recv())
                        now = time.perf_counter()
                        op = msg.get("op")
                        if op == "ack" and msg.get("id") == i:
                            ack = msg
                            out["ack"].append(now - t_send)
                        elif op == "error":
                            raise RuntimeError(msg.get("detail"))
                        elif op == "state":
                            last = msg
                            if (
                                t_target is None
                                and ack is not None
                                and msg["tick"] >= ack["tick"]
                                and abs(msg["target"][joint] - ack["target"][joint]) < 1e-9
                            ):
                                t_target = now
                                out["target"].append(now - t_send)
                            if t_moved is None and (msg["position"][joint] - pos0) * delta >= (
                                MOVED * abs(delta)
                            ):
                                t_moved = now
                                out["moved"].append(now - t_send)
            except TimeoutError:
                counts["timeouts"] += 1
            except RuntimeError:
                counts["errors"] += 1
    return counts


async def _measure(server: common.Server, commands: int, controllers: int, budget: float):
    k = max(1, min(controllers, server.nworld))
    per = [commands // k + (1 if i < commands % k else 0) for i in range(k)]
    out: dict[str, list[float]] = {"ack": [], "target": [], "moved": []}
    deadline = time.perf_counter() + budget
    t0 = time.perf_counter()
    counts = await asyncio.gather(
        *(
            _controller(f"{server.ws_url}/v1/ws/worlds/{w}?rate={RATE:g}", per[w], out, deadline)
            for w in range(k)
        )
    )
    wall = time.perf_counter() - t0
    total = {key: sum(c[key] for c in counts) for key in counts[0]}
    return out, total, wall, k


def measure(
    server: common.Server, commands: int, controllers: int = 4, budget: float = 600.0
) -> dict[str, Any]:
    """Latency samples against a running realtime server."""
    t_info, info0 = server.get_info()
    out, counts, wall, k = asyncio.run(_measure(server, commands, controllers, budget))
    t_info1, info1 = server.get_info()
    return {
        "nworld": server.nworld,
        "controllers": k,
        "joint": JOINT,
        "delta": DELTA,
        "moved_threshold_rad": MOVED,
        **counts,
        "wall_s": wall,
        "realtime_factor": common.rtf(
            info1["tick"] - info0["tick"], info1["control_hz"], t_info1 - t_info
        ),
        "tick_ms": 1e3 / info1["control_hz"],
        "ack": common.summary_ms(out["ack"]),
        "target": common.summary_ms(out["target"]),
        "moved": common.summary_ms(out["moved"]),
    }


def run(
    sizes: Sequence[int] = SIZES,
    commands: int = 1000,
    controllers: int | None = None,
    device: str = "cpu",
    servers: dict[int, common.Server] | None = None,
    progress: Callable[[str], None] | None = print,
) -> dict[str, Any]:
    """Section 4 at each size; uses a server from `servers` when one of that size is given.

    `controllers`: sockets side by side (None: `controllers_for(size)`).
    """
    started = common.now_iso()
    say = progress or (lambda _msg: None)
    results: dict[str, Any] = {}
    errors: dict[str, str] = {}
    for n in sizes:
        t0 = time.perf_counter()
        k = controllers or controllers_for(n)
        try:
            if servers and n in servers:
                res = measure(servers[n], commands, k)
            else:
                with common.running_server(n, "realtime", device) as server:
                    res = measure(server, commands, k)
        except Exception as exc:
            errors[str(n)] = f"{type(exc).__name__}: {exc}"
            say(f"  {n:>6} worlds  latency FAILED: {exc}")
            continue
        results[str(n)] = res
        say(
            f"  {n:>6} worlds  latency target p50 {res['target']['p50_ms']} ms, moved p50 "
            f"{res['moved']['p50_ms']} ms, RTF {res['realtime_factor']:.2f} "
            f"({time.perf_counter() - t0:.1f} s)"
        )
    data = {
        "device": device,
        "mode": "realtime",
        "socket": f"/v1/ws/worlds/{{w}}?rate={RATE:g} (a frame every tick)",
        "commands_per_size": commands,
        "sizes": list(sizes),
        "results": results,
        "errors": errors,
    }
    return common.section_payload(SECTION, device, data, started)


def table(payload: dict[str, Any]):
    from rich import box
    from rich.table import Table

    t = Table(
        title=f"4. WebSocket increment latency, realtime mode, ms ({payload['device']})",
        box=box.SIMPLE_HEAD,
    )
    cols = ("worlds", "n", "ack p50", "ack p99", "target p50", "target p99")
    for col in (*cols, "moved p50", "moved p99", "RTF", "timeouts"):
        t.add_column(col, justify="right")

    def f(x: float | None) -> str:
        return "-" if x is None else f"{x:.1f}"

    for n, r in payload["results"].items():
        t.add_row(
            n,
            str(r["target"]["n"]),
            f(r["ack"]["p50_ms"]),
            f(r["ack"]["p99_ms"]),
            f(r["target"]["p50_ms"]),
            f(r["target"]["p99_ms"]),
            f(r["moved"]["p50_ms"]),
            f(r["moved"]["p99_ms"]),
            f"{r['realtime_factor']:.2f}",
            str(r["timeouts"]),
        )
    return t


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.latency", description=__doc__)
    p.add_argument("--worlds", type=int, nargs="+", default=list(SIZES))
    p.add_argument("--quick", action="store_true", help="100 commands per size")
    p.add_argument("--commands", type=int, help="commands per size (default 1000)")
    p.add_argument(
        "--controllers", type=int, help="sockets commanding side by side (default 4, 8 >= 64)"
    )
    p.add_argument("--device", default="cpu")
    args = p.parse_args(argv)
    d = defaults(args.quick)
    payload = run(args.worlds, args.commands or d["commands"], args.controllers, args.device)
    path = common.write_json(f"{SECTION}{common.suffix_for(args.device)}.json", payload)
    common.console().print(table(payload))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
