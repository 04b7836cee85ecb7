"""Time control: pause, resume, switch mode, and step while paused."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, HTTPException

from service.api.deps import Loop
from service.loop import NotPausedError
from service.schemas import ModeRequest, SimReply, StepRequest
from service.types import Mode

router = APIRouter(prefix="/v1/sim", tags=["sim"])


@router.post("/pause", response_model=SimReply, summary="Stop advancing time (mode paused)")
async def pause(loop: Loop) -> SimReply:
    loop.set_mode(Mode.PAUSED)
    return SimReply(mode=loop.mode, tick=loop.tick)


@router.post("/resume", response_model=SimReply, summary="Advance in real time again")
async def resume(loop: Loop) -> SimReply:
    loop.set_mode(Mode.REALTIME)
    return SimReply(mode=loop.mode, tick=loop.tick)


@router.post("/mode", response_model=SimReply, summary="Switch to realtime, fast or paused")
async def set_mode(loop: Loop, body: ModeRequest) -> SimReply:
    loop.set_mode(body.mode)
    return SimReply(mode=loop.mode, tick=loop.tick)


@router.post(
    "/step",
    response_model=SimReply,
    summary="Paused only: advance exactly `ticks` control ticks; replies once they are done",
    responses={409: {"description": "not paused"}},
)
async def step(loop: Loop, body: StepRequest) -> SimReply:
    try:
        fut = loop.step(body.ticks)
    except NotPausedError as exc:
        raise HTTPException(409, str(exc)) from None
    tick = await asyncio.wrap_future(fut)
    return SimReply(mode=loop.mode, tick=tick)
