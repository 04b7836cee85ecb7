"""Runtime: what one running service holds (engine, loop, control, hub, surfaces), start and stop.

The engine is built off the event loop because the first build compiles kernels (tens of
seconds cold); the HTTP server is up meanwhile, `/healthz` answers and `/readyz` says 503.
Surfaces are optional add-ons (ROS 2 bridge, Foxglove server, recorder, ...) that command through
`control` and listen through `loop.add_sink`; they start once the loop runs and stop before it.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Protocol

from service.control import Control
from service.hub import StreamHub
from service.loop import SimLoop
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

    @property
    def ready(self) -> bool:
        return self.loop is not None

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
        loop.start()
        self.loop = loop
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

    def stop(self) -> None:
        for surface in reversed(self.surfaces):
            try:
                surface.stop()
            except Exception:
                log.exception("surface %s failed to stop", surface.name)
        if self.loop is not None:
            self.loop.stop()
            self.loop.batch.close()
