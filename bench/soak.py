"""Load with nothing lost: many WebSocket clients pressing ±0.01 on many worlds for a long time.

Each client holds one `/v1/ws/worlds/{w}` socket (client i on world i % worlds, states at 1 Hz so
that the frames do not dominate) and sends `increment` commands with ids at ~`rate` per second
with jitter, without waiting for acks. At the end it checks what a user relies on:

* every command got exactly one reply, an ack, in the order sent (ids matched one by one);
* no ack says `clamped` (the clients steer their own sum back towards zero, so no limit is hit);
* every world's final target (read over HTTP after the last ack) is exactly home plus the sum of
  the deltas acked for it, computed in integer hundredths;
* the server's memory (RSS of the service process and its shard workers) grew by at most
  `max_rss_growth_mb` from warm-up to the end;
* the loop's real-time factor, sampled every couple of seconds, is reported.

`soak(...)` runs against a server that is already up (tests/test_soak.py uses the suite's
harness); `run(...)` starts one (`armfleet bench` section "soak", or `python -m bench.soak`).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import httpx
import orjson
import psutil
import websockets

from bench import common
from bench.registry import Context, Result, section

ARM_JOINTS = 6  # the finger (0..0.7 rad from 0) would clamp at once; the arm has room
# The joints walked: shoulder pan and wrist 3 turn the gripper at its height, clear of the
# table. Shoulder lift, elbow and the other wrists, walked ±0.6 rad by a world's three clients,
# would at times drive it into the table: a protective stop, its increments refused (409).
WALKED = (0, 5)
STEP = 0.01
STEER_AT = 20  # hundredths: past this a client's own sum on a joint is steered back to zero


@dataclass
class ClientLog:
    """What one client sent and heard."""

    world: int
    sent: list[str] = field(default_factory=list)
    sent_at: dict[str, float] = field(default_factory=dict)
    hundredths: dict[str, tuple[int, int]] = field(default_factory=dict)  # id → (joint, ±1)
    replies: list[dict[str, Any]] = field(default_factory=list)
    ack_s: list[float] = field(default_factory=list)
    closed: str | None = None


@dataclass
class SoakResult:
    clients: int
    worlds: int
    rate_per_client: float
    duration_s: float
    commands_sent: int
    acks: int
    errors: int
    refused: int  # of the errors: refusals naming a limit ("rate: ...", "busy: ..."), not lost
    missing: int
    duplicates: int
    out_of_order: int
    clamped: int
    worlds_wrong: int
    max_target_error: float
    ack_latency: dict[str, Any]
    rss_mb_before: float | None
    rss_mb_after: float | None
    rss_growth_mb: float | None
    rtf_mean: float | None
    rtf_min: float | None
    commands_per_s: float
    problems: list[str]
    rtf_window: float | None = None  # ticks over the whole load window / its wall time

    @property
    def ok(self) -> bool:
        return not self.problems


def rss_mb(pid: int | None) -> float | None:
    """RSS of a process and its children (the shard workers) in MB."""
    if pid is None:
        return None
    try:
        proc = psutil.Process(pid)
        procs = [proc, *proc.children(recursive=True)]
        return sum(p.memory_info().rss for p in procs) / 1e6
    except psutil.Error:
        return None


async def _client(
    ws_url: str, index: int, log: ClientLog, rate: float, stop_at: float, seed: int
) -> None:
    rng = random.Random(seed * 100_003 + index)
    own = [0] * ARM_JOINTS  # this client's sum per joint, in hundredths
    url = f"{ws_url}/v1/ws/worlds/{log.world}?rate=1"
    async with websockets.connect(url, max_size=1 << 22, open_timeout=30) as ws:
        caught_up = asyncio.Event()  # every command sent so far has its reply

        async def read() -> None:
            async for raw in ws:
                msg = orjson.loads(raw)
                if msg.get("op") in ("ack", "error"):
                    now = time.perf_counter()
                    log.replies.append(msg)
                    sent = log.sent_at.get(str(msg.get("id")))
                    if sent is not None:
                        log.ack_s.append(now - sent)
                    if len(log.replies) >= len(log.sent):
                        caught_up.set()

        reader = asyncio.create_task(read())
        await asyncio.sleep(rng.uniform(0, 1 / rate))  # spread the clients' phases
        n = 0
        while time.monotonic() < stop_at:
            joint = rng.choice(WALKED)
            sign = rng.choice((-1, 1))
            if abs(own[joint]) >= STEER_AT:
                sign = -1 if own[joint] > 0 else 1
            own[joint] += sign
            msg_id = f"c{index}-{n}"
            n += 1
            log.sent.append(msg_id)
            log.hundredths[msg_id] = (joint, sign)
            log.sent_at[msg_id] = time.perf_counter()
            caught_up.clear()
            body = {"op": "increment", "joint": joint, "delta": sign * STEP, "id": msg_id}
            await ws.send(orjson.dumps(body).decode())
            await asyncio.sleep(rng.uniform(0.5, 1.5) / rate)
        try:
            await asyncio.wait_for(caught_up.wait(), timeout=30)
        except TimeoutError:
            log.closed = f"{len(log.sent) - len(log.replies)} replies missing after 30 s"
        if reader.done() and reader.exception() is not None:
            exc = reader.exception()
            log.closed = f"reader failed: {type(exc).__name__}: {exc}"
        reader.cancel()


async def soak(
    url: str,
    clients: int = 200,
    worlds: int = 64,
    rate: float = 5.0,
    duration: float = 600.0,
    server_pid: int | None = None,
    seed: int = 7,
    warmup: float = 5.0,
    max_rss_growth_mb: float = 64.0,
    say: Callable[[str], None] = lambda _: None,
) -> SoakResult:
    """Drive the service at `url` for `duration` seconds and check that nothing was lost."""
    ws_url = url.replace("http://", "ws://", 1)
    async with httpx.AsyncClient(base_url=url, timeout=30) as http:
        info = (await http.get("/v1/info")).raise_for_status().json()
        if info["nworld"] < worlds:
            raise ValueError(f"the service has {info['nworld']} worlds, the soak needs {worlds}")
        home = [j["home"] for j in info["joints"]]
        (await http.post("/v1/reset", json={"worlds": list(range(worlds))})).raise_for_status()
        await asyncio.sleep(warmup)  # allocator and caches settle before the baseline
        rss_before = rss_mb(server_pid)
        logs = [ClientLog(world=i % worlds) for i in range(clients)]
        rtfs: list[float] = []
        t0 = time.monotonic()
        stop_at = t0 + duration
        # (time, /v1/info) when the clients start and at the last sample: the window's RTF
        window = [(t0, (await http.get("/v1/info")).json())]

        async def sample_rtf() -> None:
            while time.monotonic() < stop_at:
                await asyncio.sleep(2.0)
                with_info = (await http.get("/v1/info")).json()
                rtfs.append(float(with_info["realtime_factor"]))
                window[1:] = [(time.monotonic(), with_info)]
                done = time.monotonic() - t0
                if int(done) % 60 < 2:
                    sent = sum(len(g.sent) for g in logs)
                    say(f"  soak: {done:.0f} s, {sent} commands, RTF {rtfs[-1]:.3f}")

        sampler = asyncio.create_task(sample_rtf())
        tasks = [
            asyncio.create_task(_client(ws_url, i, logs[i], rate, stop_at, seed))
            for i in range(clients)
        ]
        outcomes = await asyncio.gather(*tasks, return_exceptions=True)
        sampler.cancel()
        elapsed = time.monotonic() - t0
        states = (await http.get("/v1/worlds/state", params={"worlds": f"0-{worlds - 1}"})).json()
        rss_after = rss_mb(server_pid)
    result = _judge(
        logs, outcomes, states, home, clients, worlds, rate, elapsed, rss_before, rss_after, rtfs,
        max_rss_growth_mb,
    )  # fmt: skip
    if len(window) == 2:
        result.rtf_window = round(common.rtf_between(window[0], window[1]), 3)
    return result


def _judge(
    logs: list[ClientLog],
    outcomes: list[Any],
    states: dict[str, Any],
    home: list[float],
    clients: int,
    worlds: int,
    rate: float,
    elapsed: float,
    rss_before: float | None,
    rss_after: float | None,
    rtfs: list[float],
    max_rss_growth_mb: float,
) -> SoakResult:
    problems: list[str] = []
    for i, out in enumerate(outcomes):
        if isinstance(out, BaseException):
            problems.append(f"client {i}: {type(out).__name__}: {out}")
    acked = [[0] * ARM_JOINTS for _ in range(worlds)]
    acks = errors = refused = missing = duplicates = out_of_order = clamped = 0
    for i, log in enumerate(logs):
        if log.closed:
            problems.append(f"client {i}: {log.closed}")
        ids = [str(r.get("id")) for r in log.replies]
        seen: set[str] = set()
        for r in log.replies:
            rid = str(r.get("id"))
            if rid in seen:
                duplicates += 1
            seen.add(rid)
            if r.get("op") == "error":
                errors += 1
                refused += str(r.get("detail", "")).startswith(("rate:", "busy:"))
                continue
            acks += 1
            if r.get("clamped"):
                clamped += 1
            step = log.hundredths.get(rid)
            if step is not None:
                acked[log.world][step[0]] += step[1]
        missing += len(set(log.sent) - seen)
        if ids != log.sent[: len(ids)]:
            out_of_order += 1
    by_world = {w["world"]: w["target"] for w in states["worlds"]}
    worst = 0.0
    wrong = 0
    for w in range(worlds):
        expected = [round(home[j] + acked[w][j] / 100, 9) for j in range(ARM_JOINTS)]
        got = by_world[w][:ARM_JOINTS]
        err = max(abs(a - b) for a, b in zip(expected, got, strict=True))
        worst = max(worst, err)
        if err > 1e-9:
            wrong += 1
    growth = None if rss_before is None or rss_after is None else rss_after - rss_before
    sent = sum(len(g.sent) for g in logs)
    for what, n in (
        ("errors (other than refusals naming a limit)", errors - refused),
        ("commands without a reply", missing),
        ("duplicate replies", duplicates),
        ("clients with replies out of order", out_of_order),
        ("clamped acks", clamped),
        ("worlds whose target is not home + acked deltas", wrong),
    ):
        if n:
            problems.append(f"{n} {what}")
    if growth is not None and growth > max_rss_growth_mb:
        problems.append(f"server RSS grew {growth:.1f} MB (limit {max_rss_growth_mb:g})")
    return SoakResult(
        clients=clients,
        worlds=worlds,
        rate_per_client=rate,
        duration_s=round(elapsed, 1),
        commands_sent=sent,
        acks=acks,
        errors=errors,
        refused=refused,
        missing=missing,
        duplicates=duplicates,
        out_of_order=out_of_order,
        clamped=clamped,
        worlds_wrong=wrong,
        max_target_error=worst,
        ack_latency=common.summary_ms([s for g in logs for s in g.ack_s]),
        rss_mb_before=None if rss_before is None else round(rss_before, 1),
        rss_mb_after=None if rss_after is None else round(rss_after, 1),
        rss_growth_mb=None if growth is None else round(growth, 1),
        rtf_mean=round(sum(rtfs) / len(rtfs), 3) if rtfs else None,
        rtf_min=round(min(rtfs), 3) if rtfs else None,
        commands_per_s=round(sent / elapsed, 1) if elapsed else 0.0,
        problems=problems,
    )


DURATION_ENV = "ARMFLEET_SOAK_DURATION"  # seconds, for `armfleet bench --section 14`


@section(14, "soak", default_on=())
def soak_section(ctx: Context) -> Result:
    """Load with nothing lost: 200 WebSocket clients on 64 worlds

    The soak as a bench section (not run by default: it takes 10 minutes).

    ARMFLEET_SOAK_DURATION sets the seconds (default 600; 60 with --quick).
    """
    duration = float(os.environ.get(DURATION_ENV) or ctx.pick(600.0, 60.0))
    result = run(duration=duration, say=ctx.say, device=ctx.device)
    lat = result.ack_latency
    rows = [
        {
            "clients": result.clients,
            "worlds": result.worlds,
            "s": result.duration_s,
            "commands": result.commands_sent,
            "acks": result.acks,
            "lost/dup/reordered": f"{result.missing}/{result.duplicates}/{result.out_of_order}",
            "worlds wrong": result.worlds_wrong,
            "ack p50/p99 ms": f"{lat['p50_ms']}/{lat['p99_ms']}",
            "RSS MB before/after": f"{result.rss_mb_before}/{result.rss_mb_after}",
            "RTF mean/min": f"{result.rtf_mean}/{result.rtf_min}",
        }
    ]
    errors = {"soak": "; ".join(result.problems)} if result.problems else {}
    return Result(rows, data={"result": asdict(result), "ok": result.ok, "errors": errors})


def run(
    clients: int = 200,
    worlds: int = 64,
    rate: float = 5.0,
    duration: float = 600.0,
    say: Callable[[str], None] = print,
    device: str = "cpu",
) -> SoakResult:
    """Start a realtime service with `worlds` worlds and soak it."""
    say(f"  soak: {clients} clients on {worlds} worlds, {rate:g}/s each, {duration:g} s")
    with common.served(worlds, "realtime", device) as srv:
        result = asyncio.run(
            soak(
                srv.url,
                clients=clients,
                worlds=worlds,
                rate=rate,
                duration=duration,
                server_pid=srv.server.process.pid,
                say=say,
            )
        )
    say(table(result))
    return result


def table(r: SoakResult) -> str:
    lat = r.ack_latency
    rows = [
        ("clients / worlds / rate", f"{r.clients} / {r.worlds} / {r.rate_per_client:g} per s"),
        ("duration", f"{r.duration_s:g} s"),
        ("commands sent / acks / errors", f"{r.commands_sent} / {r.acks} / {r.errors}"),
        ("missing / duplicate / out of order", f"{r.missing} / {r.duplicates} / {r.out_of_order}"),
        ("worlds with a wrong final target", f"{r.worlds_wrong} (max err {r.max_target_error:g})"),
        ("ack latency p50 / p99 / max", f"{lat['p50_ms']} / {lat['p99_ms']} / {lat['max_ms']} ms"),
        ("server RSS before / after", f"{r.rss_mb_before} / {r.rss_mb_after} MB"),
        ("loop RTF mean / min", f"{r.rtf_mean} / {r.rtf_min}"),
        ("verdict", "nothing lost" if r.ok else "; ".join(r.problems)),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{width}}  {v}" for k, v in rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=200)
    parser.add_argument("--worlds", type=int, default=64)
    parser.add_argument("--rate", type=float, default=5.0, help="commands/s per client")
    parser.add_argument("--duration", type=float, default=600.0, help="seconds")
    args = parser.parse_args()
    started = common.now_iso()
    result = run(args.clients, args.worlds, args.rate, args.duration)
    data = {"result": asdict(result), "ok": result.ok}
    common.write_json("soak.json", {"section": "soak", "started": started, **data})
    raise SystemExit(0 if result.ok else 1)


if __name__ == "__main__":
    main()
