"""GET /v1/info: what is simulated, where, and how fast it is going."""

from __future__ import annotations

from fastapi import APIRouter

from service.api.deps import Loop
from service.core.contract.replies import Info

router = APIRouter(prefix="/v1", tags=["info"])


@router.get("/info", response_model=Info, summary="Robot, joints, batch size, timing and speed")
async def info(loop: Loop) -> Info:
    batch = loop.batch
    stats = loop.stats
    return Info(
        robot=batch.spec.name,
        joints=list(batch.spec.joints),
        nworld=batch.nworld,
        device=batch.device_name,
        shards=batch.shards,
        control_hz=batch.control_hz,
        physics_dt=batch.physics_dt,
        substeps=batch.substeps,
        mode=loop.mode,
        tick=loop.tick,
        sim_time=loop.tick * batch.tick_dt,
        ticks_per_s=stats.ticks_per_s,
        realtime_factor=stats.realtime_factor,
        captured=batch.captured,
    )
