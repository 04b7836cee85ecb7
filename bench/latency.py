"""Section 4: command latency over the WebSocket, in realtime mode.

A controller on ``/v1/ws/worlds/{w}?rate=60`` (a frame every tick) sends ``increment`` on
``wrist_3_joint``, alternating +0.1 / -0.1 so the arm stays in range, and measures from the send:

* ``ack``: the ack reply;
* ``target``: the first state frame with ``tick >= ack.tick`` whose target equals the ack's;
* ``moved``: the first state frame where the joint has moved >= 0.01 rad in the commanded
  direction from where the last frame before the send had it.

Then it sends the next one. `controllers` sockets (on worlds 0..k-1; 4, or 8 from 64 worlds up,
where ticks are slow) run side by side to collect the samples sooner; the count is in the JSON.

Standalone: ``python -m bench.latency --quick --worlds 16``.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import orjson
import websockets.asyncio.client as ws_client

from bench import common
from bench.registry import Context, Result, section

SIZES = (16, 64, 256)  # the latency target is stated at 64 worlds
JOINT = "wrist_3_joint"
DELTA = 0.1
MOVED = 0.01
COMMAND_TIMEOUT = 10.0
RATE = 60.0  # frames/s each controller asks for: every tick of the 60 Hz loop


def controllers_for(nworld: int) -> int:
    """Sockets commanding side by side: more where ticks are slow, so samples come in sooner."""
    return 4 if nworld < 64 else 8


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


async def _measure(server: common.Served, commands: int, controllers: int, budget: float):
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


def measure(server: common.Served, commands: int, controllers: int, budget: float = 600.0) -> dict:
    """Latency samples against a running realtime server."""
    before = server.get_info()
    out, counts, wall, k = asyncio.run(_measure(server, commands, controllers, budget))
    after = server.get_info()
    return {
        "nworld": server.nworld,
        "controllers": k,
        "joint": JOINT,
        "delta": DELTA,
        "moved_threshold_rad": MOVED,
        **counts,
        "wall_s": wall,
        "realtime_factor": common.rtf_between(before, after),
        "tick_ms": 1e3 / after[1]["control_hz"],
        "ack": common.summary_ms(out["ack"]),
        "target": common.summary_ms(out["target"]),
        "moved": common.summary_ms(out["moved"]),
    }


@section(4, "latency")
def latency(ctx: Context) -> Result:
    """WebSocket increment latency, realtime mode, ms

    A realtime server per size, `controllers_for(size)` sockets sending increments."""
    commands = ctx.pick(1000, 100)
    sizes = ctx.sizes(SIZES)

    def one(n: int) -> dict[str, Any]:
        with ctx.serve(n, "realtime") as server:
            return measure(server, commands, controllers_for(n))

    results, errors = ctx.each(
        sizes,
        one,
        lambda r: (
            f"latency target p50 {r['target']['p50_ms']} ms, moved p50 "
            f"{r['moved']['p50_ms']} ms, RTF {r['realtime_factor']:.2f}"
        ),
    )
    rows = []
    for n, r in results.items():
        row: dict[str, Any] = {"worlds": int(n), "n": r["target"]["n"]}
        for what in ("ack", "target", "moved"):
            row |= {f"{what} p50": r[what]["p50_ms"], f"{what} p99": r[what]["p99_ms"]}
        rows.append(row | {"RTF": r["realtime_factor"], "timeouts": r["timeouts"]})
    return Result.per_size(
        rows,
        results,
        errors,
        {
            "mode": "realtime",
            "socket": f"/v1/ws/worlds/{{w}}?rate={RATE:g} (a frame every tick)",
            "commands_per_size": commands,
            "sizes": sizes,
        },
    )


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
