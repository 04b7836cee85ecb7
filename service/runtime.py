"""Runtime: what one running service holds (engine, loop, hub) and how it starts and stops.

The engine is built off the event loop because the first build compiles kernels (tens of
seconds cold); the HTTP server is up meanwhile, `/healthz` answers and `/readyz` says 503.
"""

from __future__ import annotations

import asyncio
import logging

from service.engine import WorldBatch
from service.hub import StreamHub
from service.loop import SimLoop
from service.settings import Settings
from service.shards import ShardedBatch, auto_shards

log = logging.getLogger("armfleet")


def build_batch(s: Settings, shards: int) -> WorldBatch | ShardedBatch:
    kwargs = {"device": s.device, "control_hz": s.control_hz, "physics_dt": s.physics_dt}
    if s.ray:
        from service.ray_shards import RayBatch  # imports Ray only when asked for

        return RayBatch(s.worlds, s.shards, address=s.ray, **kwargs)
    if shards > 1:
        return ShardedBatch(s.worlds, shards, **kwargs)
    return WorldBatch(s.worlds, **kwargs)


class Runtime:
    def __init__(self, settings: Settings):
        self.settings = settings
        self.loop: SimLoop | None = None
        self.hub: StreamHub | None = None
        self.error: str | None = None

    @property
    def ready(self) -> bool:
        return self.loop is not None

    async def start(self) -> None:
        s = self.settings
        shards = s.shards or auto_shards(s.worlds, s.device)
        try:
            batch = await asyncio.to_thread(build_batch, s, shards)
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            log.exception("engine failed to start")
            return
        self.hub = StreamHub(asyncio.get_running_loop())
        loop = SimLoop(batch, s.mode, self.hub)
        loop.start()
        self.loop = loop
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
        if self.loop is not None:
            self.loop.stop()
            self.loop.batch.close()
