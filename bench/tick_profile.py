"""Section 18: where a served tick's time goes, on the device and on the host.

The service is built in this process (engine, SimLoop in fast mode, StreamHub on an event loop
thread) with one subscriber of every world at 30 Hz, binary or JSON frames, and no socket: what
is left out is only the WebSocket send, which section 7 measures end to end. Every stage is timed
where it runs:

* sim thread: ``step`` (the captured tick and the wait for it), ``snapshot`` (the host copy the
  loop publishes), ``frames`` (the device-side packing and copy of what frames carry, when the
  engine streams that way) and ``loop`` (everything else the loop does between ticks);
* the hub's thread or event loop: ``render`` (building the frame bytes from what was published).

``graph_ms`` is the engine's captured tick replayed alone (device time per tick, the floor), so
``host_ms_per_tick = wall per tick - graph_ms`` is what the host adds.

Standalone: ``python -m bench.tick_profile --device cuda --worlds 16384 65536``.
"""

from __future__ import annotations

import asyncio
import dataclasses
import statistics
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

from bench.registry import Context, Result, section

WINDOW_S = 4.0
SETTLE_TICKS = 240  # ticks from home before anything is timed (bench.throughput)


class Stages:
    """Seconds spent per stage name (thread-safe enough: one writer per stage)."""

    def __init__(self) -> None:
        self.spent: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)

    def wrap(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.spent[name] += time.perf_counter() - t0
                self.calls[name] += 1

        return timed


def _graph_ms(batch: Any, seconds: float = 1.0) -> float | None:
    """The captured tick replayed alone, ms (None without a graph)."""
    import warp as wp

    graph = getattr(batch, "_graph", None)
    if graph is None:
        return None
    dev = batch.device
    per = []
    t_end = time.perf_counter() + seconds
    while time.perf_counter() < t_end or len(per) < 5:
        t0 = time.perf_counter()
        wp.capture_launch(graph)
        wp.synchronize_device(dev)
        per.append(time.perf_counter() - t0)
    return statistics.median(per) * 1e3


def _build(n: int, device: str) -> Any:
    if device.startswith("cuda"):
        from service.engines.warp import WorldBatch

        return WorldBatch(n, device=device)
    from service.engines.native import NativeBatch

    return NativeBatch(n)


def profile(
    n: int, device: str, fmt: str, window: float = WINDOW_S, path: str = "packed"
) -> dict[str, Any]:
    """Fast mode with one `fmt` subscriber of every world at 30 Hz; stage times per second.

    path "packed": today's batch sockets (rows packed by the engine, serialised on the hub's
    frame thread); "snapshot": frames rendered from full snapshots on the event loop, as every
    socket was before issue 20 (what the single-world and page sockets still do).
    """
    import numpy as np

    from service.core.sim.loop import SimLoop
    from service.core.sim.types import Mode
    from service.core.streams import frames, wire
    from service.core.streams.formats import FrameFormat
    from service.core.streams.hub import StreamHub, Subscription

    batch = _build(n, device)
    batch.step(SETTLE_TICKS)  # settled worlds, as the service runs them (section 17)

    def engine_ms() -> float:
        t0 = time.perf_counter()
        batch.step(20)
        return (time.perf_counter() - t0) / 20 * 1e3

    graph_ms = _graph_ms(batch)
    engine_before = engine_ms()
    stages = Stages()
    batch.step = stages.wrap("step", batch.step)
    batch.snapshot = stages.wrap("snapshot", batch.snapshot)
    if hasattr(batch, "pack_rows"):
        batch.pack_rows = stages.wrap("frames", batch.pack_rows)
    encoders = dict(frames.ENCODERS)
    for k, fn in encoders.items():
        frames.ENCODERS[k] = stages.wrap("encode", fn)

    aio = asyncio.new_event_loop()
    thread = threading.Thread(target=aio.run_forever, daemon=True)
    thread.start()
    hub = StreamHub(aio)
    loop = SimLoop(batch, Mode.FAST, sinks=(hub,))
    ids = np.arange(n)
    names = batch.spec.names
    render = wire.batch_frame_binary if fmt == "binary" else wire.batch_frame
    make = FrameFormat.batch_binary if fmt == "binary" else FrameFormat.batch
    form = make(tuple(names))
    if path != "packed":  # rendered from snapshots on the event loop instead
        form = dataclasses.replace(form, packed=None, trajectories=False)
    sub = Subscription(ids, 30.0, form, lambda s: render(s, ids, names))
    got = {"n": 0, "bytes": 0}
    stop = asyncio.Event()

    async def consume() -> None:
        hub.add(sub)
        while not stop.is_set():
            await sub.ready.wait()
            sub.ready.clear()
            frame, sub.frame = sub.frame, None
            snap, sub.latest = sub.latest, None
            if frame is None:
                if snap is None:
                    continue
                t = time.perf_counter()
                frame = hub.frame(sub, snap)
                stages.spent["render"] += time.perf_counter() - t
                stages.calls["render"] += 1
            got["n"] += 1
            got["bytes"] += len(frame)

    task = asyncio.run_coroutine_threadsafe(consume(), aio)
    loop.start()
    try:
        time.sleep(1.0)
        tick0, spent0, calls0, frames0 = (
            loop.tick,
            dict(stages.spent),
            dict(stages.calls),
            dict(got),
        )
        w0 = time.perf_counter()
        time.sleep(window)
        wall = time.perf_counter() - w0
        tick1, spent1, calls1, frames1 = (
            loop.tick,
            dict(stages.spent),
            dict(stages.calls),
            dict(got),
        )
    finally:
        loop.stop()
        hub.stop()
        frames.ENCODERS.update(encoders)
        aio.call_soon_threadsafe(stop.set)
        aio.call_soon_threadsafe(sub.ready.set)
        task.result(timeout=10)
        aio.call_soon_threadsafe(aio.stop)
        thread.join(timeout=5)
    engine_after = engine_ms()  # the loop has stopped: the same batch, alone, just after
    engine_ms_per_tick = (engine_before + engine_after) / 2
    ticks = tick1 - tick0
    per_s = {k: (spent1.get(k, 0.0) - spent0.get(k, 0.0)) / wall for k in spent1}
    calls = {k: calls1.get(k, 0) - calls0.get(k, 0) for k in calls1}
    ms_per_tick = wall / ticks * 1e3 if ticks else None
    sim_busy = sum(per_s.get(k, 0.0) for k in ("step", "snapshot", "frames"))
    per_s["loop"] = max(0.0, 1.0 - sim_busy)  # the rest of the sim thread's second
    nframes = frames1["n"] - frames0["n"]
    return {
        "nworld": n,
        "format": fmt,
        "path": path,
        "substeps": batch.substeps,
        "graph_ms": graph_ms,
        "engine_ms_per_tick": engine_ms_per_tick,
        "engine_ms_before_after": [engine_before, engine_after],
        "served_ms_per_tick": ms_per_tick,
        "served_vs_engine": engine_ms_per_tick / ms_per_tick if ms_per_tick else None,
        "host_ms_per_tick": (ms_per_tick - graph_ms) if ms_per_tick and graph_ms else None,
        "ticks_per_s": ticks / wall,
        "frames_per_s": nframes / wall,
        "frame_bytes": (frames1["bytes"] - frames0["bytes"]) / nframes if nframes else None,
        "seconds_per_s": per_s,
        "ms_per_call": {
            k: per_s[k] * wall / calls[k] * 1e3 for k in calls if calls.get(k) and k in per_s
        },
        "calls_per_s": {k: v / wall for k, v in calls.items()},
    }


@section(18, "tick_profile", ("cpu", "cuda"), default_on=("cuda",))
def tick_profile(ctx: Context) -> Result:
    """Where a served tick goes: device vs host stages

    Both frame paths, both formats, at each size: the profile before and after issue 20."""
    sizes = ctx.sizes((16384, 65536) if ctx.cuda else (256, 1024), (1024,))
    window = ctx.pick(WINDOW_S, 2.0)
    out: dict[str, Any] = {}
    errors: dict[str, str] = {}
    for path in ("snapshot", "packed"):
        for fmt in ("binary", "json"):
            res, err = ctx.each(
                sizes,
                lambda n, fmt=fmt, path=path: profile(n, ctx.device, fmt, window, path),
                lambda r: (
                    f"{r['path']} {r['format']}: served {r['served_ms_per_tick']:.2f} ms/tick "
                    f"vs engine {r['engine_ms_per_tick']:.2f} ({r['served_vs_engine']:.2f}x), "
                    f"{r['frames_per_s']:.1f} frames/s"
                ),
            )
            out[f"{path}/{fmt}"] = res
            errors.update({f"{path}/{fmt}/{k}": v for k, v in err.items()})
    rows = []
    for key, res in out.items():
        for n, r in res.items():
            row = {
                "worlds": int(n),
                "path/frames": key,
                "graph ms": r["graph_ms"],
                "engine ms": r["engine_ms_per_tick"],
                "served ms": r["served_ms_per_tick"],
                "served/engine": r["served_vs_engine"],
                "frames/s": r["frames_per_s"],
            }
            for k in ("step", "snapshot", "frames", "render", "encode"):
                row[f"{k} s/s"] = r["seconds_per_s"].get(k)
            rows.append(row)
    notes = [
        "s/s: seconds of each stage per wall second: step, snapshot, frames on the sim thread; "
        "render on the event loop (snapshot path); encode on the hub's frame thread (packed)",
        "engine ms: WorldBatch.step(1) of the same batch alone, just before and just after the "
        "window (mean); every batch first runs 240 ticks from home (section 17)",
    ]
    return Result(rows, {"results": out, "errors": errors}, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
