"""Prometheus metrics: what the loop, the commands, the streams and the engine are doing.

One registry per service (not the process-global one) so that several services in one process
(tests) do not collide. Counters that happen on the sim thread (ticks, their duration, faults,
commands coming into effect) are fed by `on_tick`, which the loop calls after every tick and
which only adds to plain counts (`_TickCounts`, made into series when scraped) and walks the
deque of commands waiting for their tick when one is due. Commands are counted by a control listener
(accepted) and by the surfaces (rejected, refused); levels that already live elsewhere (mode,
real-time factor, subscribers, clients, readiness) are read when scraped.
"""

from __future__ import annotations

import bisect
import collections
import functools
import itertools
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

from prometheus_client import (
    CollectorRegistry,
    Counter,
    Histogram,
    disable_created_metrics,
    generate_latest,
)
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import Collector
from prometheus_client.utils import floatToGoString
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.core.commands.registry import BY_HTTP

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
disable_created_metrics()  # the *_created series only double the output here

# Control ticks are 16.7 ms at 60 Hz: buckets from well below to several ticks.
_TICK_BUCKETS = (0.001, 0.002, 0.005, 0.01, 0.0167, 0.025, 0.05, 0.1, 0.25, 1.0)
# A command waits for the next tick boundary and that tick: 0..2 ticks when all is well.
_EFFECT_BUCKETS = (0.005, 0.01, 0.0167, 0.025, 0.0333, 0.05, 0.1, 0.25, 0.5, 1.0, 5.0)
_MAX_WAITING = 100_000  # accepted commands waiting for their tick (paused: they pile up)


class Metrics:
    """The service's metrics; `render()` is the body of GET /metrics."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        # every series lives in this service's own registry
        counter = functools.partial(Counter, registry=self.registry)
        histogram = functools.partial(Histogram, registry=self.registry)
        # ticks, their duration, world and engine faults: counted on the sim thread
        self.tick_counts = _TickCounts()
        self.registry.register(self.tick_counts)
        self.commands = counter(
            "armfleet_commands",
            "commands by surface, kind and result (accepted, rejected: invalid, "
            "refused: token/origin/rate)",
            ["source", "kind", "result"],
        )
        self.effect_seconds = histogram(
            "armfleet_command_effect_latency_seconds",
            "from a command's acceptance to the end of the first tick stepped with it",
            buckets=_EFFECT_BUCKETS,
        )
        self._levels = _Levels()
        self.registry.register(self._levels)
        # (effective tick, accepted at) of commands not yet in effect; appended from any thread,
        # drained on the sim thread. deque appends and pops are atomic.
        self._waiting: collections.deque[tuple[int, float]] = collections.deque(maxlen=_MAX_WAITING)
        self._lock = threading.Lock()
        self._command_series: dict[tuple[str, str, str], Any] = {}

    # -- fed by the service -----------------------------------------------------------------

    def command_accepted(self, source: str, kind: str, tick: int, worlds: int = 1) -> None:
        """A control listener calls this for each accepted command (`worlds` it changed: one
        that changes none, a mode switch, has no effect latency)."""
        self._series(str(source), kind, "accepted").inc()
        if worlds:
            self._waiting.append((tick, time.monotonic()))

    def command_rejected(self, source: str, kind: str, result: str = "rejected") -> None:
        """A surface calls this for a command it refused (result: rejected or refused)."""
        self._series(str(source), kind or "unknown", result).inc()

    def _series(self, source: str, kind: str, result: str) -> Any:
        """The commands counter's series of these labels, kept: `labels()` costs a lock and a
        lookup on every command, and commands come by the thousand a second."""
        key = (source, kind, result)
        series = self._command_series.get(key)
        if series is None:
            series = self._command_series[key] = self.commands.labels(source, kind, result)
        return series

    def on_tick(self, tick: int, seconds: float, faulted: int) -> None:
        """The loop calls this on the sim thread after each tick (faulted -1: the tick failed)."""
        self.tick_counts.add(seconds, faulted)
        waiting = self._waiting  # the lock and the clock only when a command is due
        if faulted < 0 or not waiting or waiting[0][0] > tick:
            return
        now = time.monotonic()
        with self._lock:
            while waiting and waiting[0][0] <= tick:
                self.effect_seconds.observe(now - waiting.popleft()[1])

    def level(self, name: str, help_text: str, read: Callable[[], float | None]) -> None:
        """A gauge read at scrape time (`read` may return None: not reported then)."""
        self._levels.add(name, help_text, read)

    def counter_level(self, name: str, help_text: str, read: Callable[[], float | None]) -> None:
        """A counter kept elsewhere (e.g. in the hub), read at scrape time."""
        self._levels.add(name, help_text, read, counter=True)

    # -- read -------------------------------------------------------------------------------

    def render(self) -> bytes:
        return generate_latest(self.registry)


class _TickCounts(Collector):
    """Ticks, their wall time as a histogram, world and engine faults: plain counts the sim
    thread adds to after every tick, made into series only when scraped. Through prometheus'
    own counter and histogram each tick cost three locked updates and a bucket search, ~12 us
    of the sim thread's time a tick on an H200's host while the device idled between two
    ticks (bench/results/issue39/gpu6 and gpu7); the series and their values are the same."""

    def __init__(self) -> None:
        self._lock = threading.Lock()  # a scrape reads every count of the same ticks
        self._buckets = [0] * (len(_TICK_BUCKETS) + 1)  # per bucket, not cumulative; +Inf last
        self._sum = 0.0
        self._ticks = self._faults = self._failed = 0

    def add(self, seconds: float, faulted: int) -> None:
        """One tick of `seconds` that reset `faulted` worlds (-1: the tick failed)."""
        with self._lock:
            if faulted < 0:
                self._failed += 1
                return
            self._ticks += 1
            self._sum += seconds
            self._buckets[bisect.bisect_left(_TICK_BUCKETS, seconds)] += 1
            self._faults += faulted

    def describe(self) -> Iterator[Metric]:
        return iter(())

    def collect(self) -> Iterator[Metric]:
        with self._lock:
            buckets, total = list(itertools.accumulate(self._buckets)), self._sum
            ticks, faults, failed = self._ticks, self._faults, self._failed
        yield CounterMetricFamily("armfleet_ticks", "control ticks stepped", value=ticks)
        bounds = [floatToGoString(b) for b in _TICK_BUCKETS] + ["+Inf"]
        yield HistogramMetricFamily(
            "armfleet_tick_duration_seconds",
            "wall time of one control tick (commands in, physics, snapshot)",
            buckets=list(zip(bounds, buckets, strict=True)),
            sum_value=total,
        )
        yield CounterMetricFamily(
            "armfleet_world_faults", "worlds reset for NaN or contact overflow", value=faults
        )
        yield CounterMetricFamily(
            "armfleet_engine_faults", "ticks that failed with an engine exception", value=failed
        )


class _Levels(Collector):
    """Values that live in other objects, read when Prometheus scrapes."""

    def __init__(self) -> None:
        self._reads: list[tuple[str, str, Callable[[], float | None], bool]] = []

    def add(
        self, name: str, help_text: str, read: Callable[[], float | None], counter: bool = False
    ) -> None:
        self._reads.append((name, help_text, read, counter))

    def describe(self) -> Iterator[Metric]:
        return iter(())  # values may be absent until the engine runs; no fixed description

    def collect(self) -> Iterator[Metric]:
        for name, help_text, read, counter in self._reads:
            try:
                value = read()
            except Exception:  # a half-started service: leave the value out
                value = None
            if value is None:
                continue
            family: Any = (
                CounterMetricFamily(name, help_text, value=value)
                if counter
                else GaugeMetricFamily(name, help_text, value=value)
            )
            yield family


def command_kind(path: str) -> str | None:
    """The command an HTTP write path stands for (for counting refusals), None if not one."""
    if not path.startswith("/v1/"):
        return None
    last = path.rstrip("/").rsplit("/", 1)[-1]
    return BY_HTTP.get(last, "other")


class CommandCounter:
    """Counts HTTP writes answered with an error: 401/403/429/503 refused, other 4xx rejected.

    (Accepted commands are counted by the control listener, whatever surface sent them.)
    """

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] in ("GET", "HEAD", "OPTIONS"):
            return await self.app(scope, receive, send)
        kind = command_kind(scope["path"])
        if kind is None:
            return await self.app(scope, receive, send)

        async def counting(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] >= 400:
                status = message["status"]
                result = "refused" if status in (401, 403, 429, 503) else "rejected"
                self.metrics.command_rejected("http", kind, result)
            await send(message)

        await self.app(scope, receive, counting)
