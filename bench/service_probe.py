"""Measuring a served batch from a client: what sections 2, 3, 7, 10, 11, 21 and the capacity
command read off `armfleet serve` while it runs.

The tick of a state frame (without parsing a frame of megabytes), a counter of one socket's
frames, `/v1/info` and the sim thread's busy counters from `/metrics`, and the two measured
windows: fast mode with every world streamed to one client (`measure_fast`), and realtime
with one subscriber a group of worlds (`measure_realtime`). Why apart from the sections: each
of those compares its own setting with these same windows, so they are written once.

The client shares the machine with the server: on a 2-core box its frame handling competes with
the server's threads, as a real co-located client would.
"""

from __future__ import annotations

import asyncio
import re
import time
from typing import Any

import httpx
import websockets.asyncio.client as ws_client

from bench import common
from clients.wire import BINARY_MAGIC

WORLDS_PER_SUBSCRIBER = 16
MIN_TICKS = 20  # fast mode: the window covers at least this many ticks ...
MAX_WINDOW = 40.0  # ... but lasts no longer than this [s]
_TICK = re.compile(r'"tick":(\d+)')


def frame_tick(frame: str | bytes) -> int | None:
    """The `tick` of a state frame without parsing the whole (possibly MB-sized) frame."""
    if isinstance(frame, bytes) and frame[:4] == BINARY_MAGIC:  # binary: JSON header after 8 bytes
        frame = frame[8:104]
    head = frame[:96] if isinstance(frame, str) else frame[:96].decode(errors="replace")
    m = _TICK.search(head)
    return int(m.group(1)) if m else None


# -- a streaming client --------------------------------------------------------------------------


class FrameCounter:
    """Reads one socket's frames, keeping count, bytes and the last tick seen."""

    def __init__(self) -> None:
        self.frames = 0
        self.bytes = 0
        self.first: tuple[float, int] | None = None  # (perf_counter, tick) while counting
        self.last: tuple[float, int] | None = None
        self.counting = False
        self.error: str | None = None

    def reset(self) -> None:
        self.frames = 0
        self.bytes = 0
        self.first = self.last = None
        self.counting = True

    async def run(self, url: str) -> None:
        try:
            async with ws_client.connect(url, max_size=None, compression=None) as ws:
                async for msg in ws:
                    if not self.counting:
                        continue
                    now = time.perf_counter()
                    tick = frame_tick(msg)
                    if tick is None:
                        continue
                    self.frames += 1
                    self.bytes += len(msg)
                    if self.first is None:
                        self.first = (now, tick)
                    self.last = (now, tick)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # reported, not raised: the measurement says what it saw
            self.error = f"{type(exc).__name__}: {exc}"


async def timed_info(client: httpx.AsyncClient, url: str) -> tuple[float, dict[str, Any]]:
    """`/v1/info`, and the moment it stands for (halfway through the request)."""
    t0 = time.perf_counter()
    r = await client.get(f"{url}/v1/info")
    t1 = time.perf_counter()
    r.raise_for_status()
    return (t0 + t1) / 2, r.json()


BUSY = {
    "engine_share": "armfleet_engine_step_seconds_total",
    "tick_share": "armfleet_tick_duration_seconds_sum",
}


async def busy(client: httpx.AsyncClient, url: str) -> dict[str, float | None]:
    """The sim thread's busy-time counters from /metrics (None: not exported)."""
    text = (await client.get(f"{url}/metrics")).text
    values: dict[str, float] = {}
    for line in text.splitlines():
        name, _, value = line.partition(" ")
        if name in BUSY.values():
            values[name] = float(value)
    return {k: values.get(metric) for k, metric in BUSY.items()}


# -- the measured windows -----------------------------------------------------------------------

SETTLE_TICKS = 240  # as bench.throughput: windows start once the worlds have settled
MAX_SETTLE_S = 30.0


async def settle(client: httpx.AsyncClient, url: str) -> None:
    """Wait (at most MAX_SETTLE_S) until the service has run SETTLE_TICKS ticks from home."""
    deadline = time.perf_counter() + MAX_SETTLE_S
    while time.perf_counter() < deadline:
        _, info = await timed_info(client, url)
        if info["tick"] >= SETTLE_TICKS:
            return
        await asyncio.sleep(0.2)


async def measure_fast(
    server: common.Served, duration: float, warmup: float, fmt: str = "json"
) -> dict[str, Any]:
    counter = FrameCounter()
    reader = asyncio.create_task(counter.run(f"{server.ws_url}/v1/ws?rate=30&format={fmt}"))
    try:
        async with httpx.AsyncClient(timeout=60) as client:
            await asyncio.sleep(warmup)
            await settle(client, server.url)
            counter.reset()
            t0, info0 = await timed_info(client, server.url)
            # Slow ticks (thousands of worlds on a CPU) get a window of >= MIN_TICKS ticks, so
            # that the whole-tick granularity of the counter stays a small error.
            tps = info0.get("ticks_per_s") or 0.0
            window = min(max(duration, MIN_TICKS / tps), MAX_WINDOW) if tps > 0 else duration
            await asyncio.sleep(window)
            t1, info1 = await timed_info(client, server.url)
            counter.counting = False
    finally:
        reader.cancel()
        await asyncio.gather(reader, return_exceptions=True)
    n, substeps = info1["nworld"], info1["substeps"]
    ticks = info1["tick"] - info0["tick"]
    wall = t1 - t0
    out: dict[str, Any] = {
        "nworld": n,
        "substeps": substeps,
        "ticks": ticks,
        "tick_last": info1["tick"],  # the window is ticks [tick_last - ticks, tick_last)
        "wall_s": wall,
        "ticks_per_s": ticks / wall,
        "world_steps_per_s": common.world_steps(ticks, n, substeps) / wall,
        "realtime_factor": common.rtf(ticks, info1["control_hz"], wall),
        "loop_ticks_per_s": info1["ticks_per_s"],  # the loop's own last 1 s window
        "frames": counter.frames,
        "frames_per_s": counter.frames / wall,
        "frame_bytes_mean": counter.bytes / counter.frames if counter.frames else None,
        "stream_error": counter.error,
        "captured": info1.get("captured"),
        "ready_s": server.ready_s,
    }
    if counter.first and counter.last and counter.last[0] > counter.first[0]:
        (ta, ka), (tb, kb) = counter.first, counter.last
        out["world_steps_per_s_frames"] = common.world_steps(kb - ka, n, substeps) / (tb - ta)
    return out


async def measure_realtime(
    server: common.Served,
    window: float,
    warmup: float,
    check_every: float = 2.0,
    abort_below: float = 0.95,
    abort_after: float = 5.0,
    per_subscriber: int = WORLDS_PER_SUBSCRIBER,
    fmt: str = "json",
) -> dict[str, Any]:
    n = server.nworld
    groups = [(lo, min(n, lo + per_subscriber) - 1) for lo in range(0, n, per_subscriber)]
    counters = [FrameCounter() for _ in groups]
    query = "" if fmt == "json" else f"&format={fmt}"
    readers = [
        asyncio.create_task(c.run(f"{server.ws_url}/v1/ws?worlds={lo}-{hi}&rate=30{query}"))
        for c, (lo, hi) in zip(counters, groups, strict=True)
    ]
    samples: list[float] = []  # the loop's own 1 s RTF, sampled during the window
    aborted = False
    try:
        async with httpx.AsyncClient(timeout=60) as client:
            await asyncio.sleep(warmup)
            for c in counters:
                c.reset()
            busy0 = await busy(client, server.url)
            t0, info0 = await timed_info(client, server.url)
            t1, info1 = t0, info0
            while t1 - t0 < window:
                await asyncio.sleep(min(check_every, max(0.05, window - (t1 - t0))))
                t1, info1 = await timed_info(client, server.url)
                samples.append(info1["realtime_factor"])
                so_far = common.rtf(info1["tick"] - info0["tick"], info1["control_hz"], t1 - t0)
                if t1 - t0 >= abort_after and so_far < abort_below:
                    aborted = True  # clearly short of real time: no need to wait out the window
                    break
            busy1 = await busy(client, server.url)
    finally:
        for r in readers:
            r.cancel()
        await asyncio.gather(*readers, return_exceptions=True)
    ticks = info1["tick"] - info0["tick"]
    wall = t1 - t0
    frames = [c.frames / wall for c in counters]
    return {
        "nworld": n,
        "subscribers": len(groups),
        "ticks": ticks,
        "wall_s": wall,
        "realtime_factor": common.rtf(ticks, info1["control_hz"], wall),
        "min_loop_rtf_1s": min(samples) if samples else None,
        "aborted_early": aborted,
        "frames_per_s_per_subscriber_min": min(frames) if frames else None,
        "frames_per_s_per_subscriber_mean": sum(frames) / len(frames) if frames else None,
        "stream_errors": sorted({c.error for c in counters if c.error}),
        "world_steps_per_s": common.world_steps(ticks, n, info1["substeps"]) / wall,
        "ready_s": server.ready_s,
        "format": fmt,
        # Shares of the window's wall time on the sim thread: stepping the engine, the loop's
        # own work in a tick (commands, snapshots, packing frames), and between ticks.
        **{k: (busy1[k] - busy0[k]) / wall for k in busy0 if busy0[k] is not None},
    }
