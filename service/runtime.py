"""Runtime: what one running service holds (engine, loop, control, hub, surfaces), start and stop.

The engine is built off the event loop because the first build compiles kernels (tens of
seconds cold); the HTTP server is up meanwhile, `/healthz` answers and `/readyz` says 503.
Surfaces are optional add-ons (ROS 2 bridge, Foxglove server, recorder, ...) that command through
`control` and listen through `loop.add_sink`; they start once the loop runs and stop before it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
from collections.abc import Callable
from typing import Any, Protocol

import orjson

from service.access import ClientSlots
from service.control import Accepted, Control
from service.hub import StreamHub
from service.loop import SimLoop
from service.metrics import Metrics
from service.settings import Settings
from service.types import Batch

log = logging.getLogger("armfleet")


class Surface(Protocol):
    """An optional way in or out of the service, started with the loop and stopped before it."""

    name: str

    def start(self, runtime: Runtime) -> None: ...

    def stop(self) -> None: ...


def build_batch(s: Settings) -> Batch:
    """The engine the settings ask for: native MuJoCo on every core, or MuJoCo Warp (split over
    CPU cores when it pays). Imported here, so that the native engine never loads warp."""
    if s.engine == "mujoco":
        from service.native import NativeBatch

        return NativeBatch(
            s.worlds,
            control_hz=s.control_hz,
            physics_dt=s.physics_dt,
            nthread=s.shards,
            device=s.device,
        )
    from service.engine import WorldBatch
    from service.shards import ShardedBatch, auto_shards

    shards = s.shards or auto_shards(s.worlds, s.device)
    kwargs = {"device": s.device, "control_hz": s.control_hz, "physics_dt": s.physics_dt}
    if s.ray:
        from service.ray_shards import RayBatch  # imports Ray only when asked for

        return RayBatch(s.worlds, s.shards, address=s.ray, **kwargs)
    if shards > 1:
        return ShardedBatch(s.worlds, shards, **kwargs)
    return WorldBatch(s.worlds, **kwargs)


class Runtime:
    def __init__(self, settings: Settings, surfaces: tuple[Surface, ...] = ()):
        self.settings = settings
        self.loop: SimLoop | None = None
        self.control: Control | None = None
        self.hub: StreamHub | None = None
        self.surfaces: list[Surface] = list(surfaces)
        self.error: str | None = None
        self.metrics = Metrics()
        self.slots = ClientSlots(settings.max_clients)  # shared by HTTP and every socket surface
        self._problems: list[str] = []
        self._watchdog: asyncio.Task[None] | None = None
        self._stopping: asyncio.Task[None] | None = None
        self._register_levels()

    @property
    def ready(self) -> bool:
        return self.loop is not None and not self.problems()

    def problems(self) -> list[str]:
        """Why the service is not ready now: starting, engine failed, tick failing, shard lost."""
        if self.loop is None:
            return [self.error or "starting (compiling kernels)"]
        out = []
        if self.loop.failure:
            out.append(f"ticks are failing: {self.loop.failure}")
        health: Callable[[], list[str]] | None = getattr(self.loop.batch, "health", None)
        if health is not None:
            out += health()
        return out

    async def _watch(self, period: float = 0.1) -> None:
        """Notice problems between requests: tell subscribers and the log when they change."""
        while True:
            await asyncio.sleep(period)
            try:
                now = self.problems()
            except Exception:
                log.exception("health check failed")
                continue
            if now != self._problems:
                self._problems = now
                status = {"op": "status", "ready": not now, "problems": now}
                if self.hub is not None:
                    self.hub.broadcast(orjson.dumps(status))
                if now:
                    log.warning("not ready: %s", "; ".join(now))
                else:
                    log.warning("ready again")

    def _register_levels(self) -> None:
        m = self.metrics
        m.level("armfleet_ready", "1 when ready for commands", lambda: float(self.ready))
        m.level("armfleet_tick", "control ticks completed", lambda: self._loop_attr("tick"))
        m.level(
            "armfleet_realtime_factor",
            "simulated seconds per wall second over the last second",
            lambda: self._loop_attr("stats").realtime_factor if self.loop else None,
        )
        m.level(
            "armfleet_ticks_per_second",
            "control ticks per wall second over the last second",
            lambda: self._loop_attr("stats").ticks_per_s if self.loop else None,
        )
        m.level(
            "armfleet_subscribers",
            "WebSocket stream subscribers",
            lambda: None if self.hub is None else self.hub.subscribers,
        )
        m.level("armfleet_clients", "clients being served now", lambda: self.slots.active)
        m.counter_level(
            "armfleet_frames_skipped",
            "state frames replaced by a newer one before a slow reader took them",
            lambda: None if self.hub is None else self.hub.frames_skipped,
        )
        m.counter_level(
            "armfleet_shard_restarts",
            "shard worker processes rebuilt after dying",
            lambda: getattr(self.loop.batch, "restarts", 0) if self.loop else None,
        )

    def _loop_attr(self, name: str) -> Any:
        return None if self.loop is None else getattr(self.loop, name)

    def _count_accepted(self, accepted: Accepted) -> None:
        self.metrics.command_accepted(accepted.source, accepted.kind, accepted.tick)

    async def start(self) -> None:
        s = self.settings
        try:
            batch = await asyncio.to_thread(build_batch, s)
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            log.exception("engine failed to start")
            return
        self.hub = StreamHub(asyncio.get_running_loop())
        loop = SimLoop(batch, s.mode, (self.hub,))
        self.control = Control(loop)
        self.control.add_listener(self._count_accepted)
        loop.add_tick_listener(self.metrics.on_tick)
        loop.start()
        self.loop = loop
        self._watchdog = asyncio.create_task(self._watch())
        for surface in self.surfaces:
            surface.start(self)
        log.info(
            "armfleet ready at http://%s:%d (docs /docs): %d worlds on %s (%d shard%s), "
            "%d substeps of %.3f ms per %.0f Hz tick, mode %s; compile %.1f s, capture %.2f s%s",
            s.host,
            s.port,
            batch.nworld,
            batch.device_name,
            batch.shards,
            "" if batch.shards == 1 else "s",
            batch.substeps,
            batch.physics_dt * 1e3,
            batch.control_hz,
            loop.mode.value,
            batch.compile_s,
            batch.capture_s,
            "" if batch.captured else f" (NOT captured: {batch.capture_error})",
        )

    def install_stop_signal(self) -> None:
        """SIGTERM: close every stream with 1001 (going away) first, then stop as usual.

        The server's own handler would close sockets with 1012; ours runs first and then hands
        over to it, so that clients learn the service is going away rather than restarting.
        """
        aio = asyncio.get_running_loop()
        previous = signal.getsignal(signal.SIGTERM)

        async def going_away() -> None:
            if self.hub is not None:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(self.hub.close_all(1001, "service stopping"), 1.0)
            if callable(previous):
                previous(signal.SIGTERM, None)
            else:
                signal.raise_signal(signal.SIGINT)

        def on_term() -> None:
            self._stopping = aio.create_task(going_away())

        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
            aio.add_signal_handler(signal.SIGTERM, on_term)

    def stop(self) -> None:
        if self._watchdog is not None:
            self._watchdog.cancel()
        for surface in reversed(self.surfaces):
            try:
                surface.stop()
            except Exception:
                log.exception("surface %s failed to stop", surface.name)
        if self.loop is not None:
            self.loop.stop()
            self.loop.batch.close()
