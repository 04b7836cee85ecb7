"""Time control: pause, resume, switch mode, and step while paused."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter

from service.api.deps import Ctl
from service.core.commands.base import HTTP
from service.core.commands.world import ModeRequest, Step, StepRequest
from service.core.contract.replies import SimReply, answers
from service.core.sim.types import Mode

router = APIRouter(prefix="/v1/sim", tags=["sim"])


@router.post("/pause", response_model=SimReply, summary="Stop advancing time (mode paused)")
async def pause(control: Ctl) -> SimReply:
    return SimReply(mode=Mode.PAUSED, tick=control.set_mode(Mode.PAUSED, HTTP))


@router.post("/resume", response_model=SimReply, summary="Advance in real time again")
async def resume(control: Ctl) -> SimReply:
    return SimReply(mode=Mode.REALTIME, tick=control.set_mode(Mode.REALTIME, HTTP))


@router.post("/mode", response_model=SimReply, summary="Switch to realtime, fast or paused")
async def set_mode(control: Ctl, body: ModeRequest) -> SimReply:
    return SimReply(mode=body.mode, tick=control.set_mode(body.mode, HTTP))


@router.post(
    "/step",
    summary="Paused only: advance exactly `ticks` control ticks; replies once they are done",
    **answers(SimReply, 409),
)
async def step(control: Ctl, body: StepRequest) -> SimReply:
    done = control.run(Step(body.ticks), HTTP)  # NotPaused → 409 (app handler)
    return SimReply(mode=control.loop.mode, tick=await asyncio.wrap_future(done))
