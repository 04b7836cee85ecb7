"""Host-side timeline of the served tick (issue 39 item 3, branch gpu6): a probe, not product code.

Loaded into `armfleet serve` through sitecustomize.py beside it (PYTHONPATH, TL_OUT=path).
It wraps the loop's stages and the engine's tick and records, for every tick while a stream
subscriber is connected: perf_counter_ns stamps (tick start, launch, sync returned, tick end),
the ns spent in each wrapped stage, and the device's own times from CUDA events around the
graph (graph time; idle gap between the end of one graph and the start of the next). Dumps
JSON after TL_TICKS recorded ticks. Per-thread CPU seconds from /proc over the same ticks.
`engine_only(n)` records the same for WorldBatch.step alone (bench's engine loop).
"""

from __future__ import annotations

import atexit
import json
import os
import time
from collections import deque

NS = time.perf_counter_ns
TL_TICKS = int(os.environ.get("TL_TICKS", "2000"))
SKIP = int(os.environ.get("TL_SKIP", "200"))  # ticks with a subscriber before recording


class Rec:
    def __init__(self) -> None:
        self.ticks: list[dict] = []
        self.cur: dict | None = None
        self.done = False
        self.seen = 0
        self.ev = None  # (start, end) events of the last tick
        self.threads0: dict | None = None
        self.names: dict = {}


R = Rec()
EVENTS: deque = deque()  # two ticks' (start, end) events, reused


def _threads() -> dict:
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                s = f.read()
            with open(f"/proc/self/task/{tid}/comm") as f:
                name = f.read().strip()
        except OSError:
            continue
        parts = s[s.rindex(")") + 2 :].split()
        out[tid] = (name, (int(parts[11]) + int(parts[12])) / os.sysconf("SC_CLK_TCK"))
    return out


def _names() -> dict:
    import threading

    return {str(t.native_id): t.name for t in threading.enumerate()}


def _spent(name: str, fn):
    def timed(*a, **k):
        c = R.cur
        if c is None:
            return fn(*a, **k)
        t0 = NS()
        try:
            return fn(*a, **k)
        finally:
            c[name] = c.get(name, 0) + NS() - t0

    return timed


def patch_engine() -> None:
    import warp as wp

    from service.engines import warp as W

    def _one_tick(self):
        c = R.cur
        if c is None or not self.device.is_cuda or self._graph is None:
            return orig(self)
        if not EVENTS:
            EVENTS.extend(wp.Event(self.device, enable_timing=True) for _ in range(4))
        EVENTS.rotate(2)
        e0, e1 = EVENTS[0], EVENTS[1]
        stream = wp.get_stream(self.device)
        c["launch"] = NS()
        stream.record_event(e0)
        wp.capture_launch(self._graph)
        stream.record_event(e1)
        c["launched"] = NS()
        nf = self._read(self._nfault)[0]
        c["synced"] = NS()
        if R.ev is not None:
            c["dev_gap_ms"] = wp.get_event_elapsed_time(R.ev[1], e0)
        c["dev_graph_ms"] = wp.get_event_elapsed_time(e0, e1)
        R.ev = (e0, e1)
        import numpy as np

        if nf:
            return np.flatnonzero(self._read(self._fault))
        return np.zeros(0, dtype=np.int64)

    orig = W.WorldBatch._one_tick
    W.WorldBatch._one_tick = _one_tick


def _finish_record(path: str, extra: dict) -> None:
    R.done = True
    t1 = _threads()
    cpu = {}
    for tid, (name, s) in t1.items():
        s0 = R.threads0.get(tid, (name, 0.0))[1] if R.threads0 else 0.0
        cpu[f"{name}:{tid}"] = s - s0
    names = {**R.names, **_names()}
    cpu = {f"{names.get(k.split(':')[1], k)}": v for k, v in cpu.items()}
    out = {"ticks": R.ticks, "thread_cpu_s": cpu, **extra}
    if not R.ticks[-1].get("next_start"):
        R.ticks.pop()
    with open(path, "w") as f:
        json.dump(out, f)


def install(path: str) -> None:
    from service.core.sim import loop as L
    from service.core.sim import snapshot_beside as SB
    from service.core.sim.listeners import Listeners

    patch_engine()
    Listeners.ticked = _spent("on_tick", Listeners.ticked)
    Listeners.counted = _spent("counted", Listeners.counted)
    SB.BesideSnapshot.finish = _spent("beside_finish", SB.BesideSnapshot.finish)
    SB.BesideSnapshot.start = _spent("beside_start", SB.BesideSnapshot.start)
    for name in ("_take_commands", "_finish_tick", "_publish", "_serve_requests"):
        setattr(L.SimLoop, name, _spent(name.strip("_"), getattr(L.SimLoop, name)))
    orig_tick = L.SimLoop._tick_once
    atexit.register(lambda: R.done or not R.ticks or _finish_record(path, {"where": "service"}))

    def _tick_once(self, mode):
        if R.done:
            return orig_tick(self, mode)
        hub = next((s for s in self.listeners.sinks if hasattr(s, "subscribers")), None)
        live = hub is not None and hub.subscribers > 0
        if live:
            R.seen += 1
        if not live or R.seen <= SKIP:
            R.cur = None
            return orig_tick(self, mode)
        if R.threads0 is None:
            R.threads0, R.names = _threads(), _names()
        prev = R.ticks[-1] if R.ticks else None
        c = R.cur = {"start": NS()}
        if prev is not None:
            prev["next_start"] = c["start"]
        try:
            return orig_tick(self, mode)
        finally:
            c["end"] = NS()
            R.ticks.append(c)
            if len(R.ticks) >= TL_TICKS:
                R.cur = None
                _finish_record(path, {"where": "service"})

    L.SimLoop._tick_once = _tick_once


def engine_only(n: int, ticks: int, path: str) -> None:
    """The bench's engine loop (section 25's `engine_over`) with the same engine stamps."""
    from service.engines.warp import WorldBatch

    patch_engine()
    batch = WorldBatch(n, device="cuda")
    batch.step(300)
    R.threads0 = _threads()
    R.done = False
    R.ticks = []
    prev = None
    for _ in range(ticks):
        c = R.cur = {"start": NS()}
        if prev is not None:
            prev["next_start"] = c["start"]
        batch.step(1)
        c["end"] = NS()
        R.ticks.append(c)
        prev = c
    R.cur = None
    _finish_record(path, {"where": "engine"})
