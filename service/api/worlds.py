"""Per-world state and commands: read JointState, press Up/Down, set targets, reset."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Body, HTTPException, Query
from fastapi.responses import Response

from service import wire
from service.api.deps import Loop, World, unprocessable
from service.commands import CommandError, resolve_joints
from service.loop import CommandResult
from service.schemas import (
    BatchCommandReply,
    BatchTargets,
    CommandReply,
    IncrementRequest,
    JointTargets,
    ResetReply,
    ResetRequest,
    WorldState,
    WorldStates,
)

router = APIRouter(prefix="/v1", tags=["worlds"])


def _json(payload: Any) -> Response:
    return Response(wire.dumps(payload), media_type="application/json")


def _reply_dict(result: CommandResult) -> dict[str, Any]:
    return {
        "world": result.world,
        "target": result.target,
        "clamped": result.clamped,
        "tick": result.tick,
    }


def _reply(result: CommandResult) -> Response:
    """CommandReply, serialised directly (the hot path of the Up/Down buttons)."""
    return _json(_reply_dict(result))


@router.get(
    "/worlds/state",
    response_model=WorldStates,
    summary="State of several worlds (default: all) at the last completed tick",
)
async def get_states(
    loop: Loop,
    worlds: Annotated[
        str | None, Query(description="ids and ranges, e.g. 0,3,7 or 0-63", examples=["0,3,7"])
    ] = None,
) -> Response:
    n = loop.batch.nworld
    try:
        ids = np.arange(n) if worlds is None else wire.parse_worlds(worlds, n)
    except IndexError as exc:
        raise HTTPException(404, str(exc)) from None
    except ValueError as exc:
        raise unprocessable(["query", "worlds"], str(exc)) from None
    snap = await asyncio.wrap_future(loop.fresh_snapshot())
    return _json(wire.states(snap, ids, loop.spec.names))


@router.get(
    "/worlds/{world}/state",
    response_model=WorldState,
    summary="One world's JointState, target and flange pose at the last completed tick",
)
async def get_state(loop: Loop, world: World) -> Response:
    snap = await asyncio.wrap_future(loop.fresh_snapshot())
    return _json(wire.world_state(snap, world, loop.spec.names))


@router.post(
    "/worlds/{world}/increments",
    response_model=CommandReply,
    summary="Add to joint targets (the seed's Up/Down buttons); clamps to the joint range",
)
async def increment(loop: Loop, world: World, body: IncrementRequest) -> Response:
    field = "deltas" if body.deltas is not None else "joint"
    try:
        deltas = resolve_joints(loop.spec, body.as_mapping(), field)
        return _reply(loop.increment(world, deltas))
    except CommandError as exc:
        raise unprocessable(["body", *exc.field.split(".")], exc.message) from None


@router.put(
    "/worlds/{world}/targets",
    response_model=CommandReply,
    summary="Set targets, JointState-shaped; a subset of names keeps the others' targets",
)
async def put_targets(loop: Loop, world: World, body: JointTargets) -> Response:
    try:
        values = resolve_joints(loop.spec, dict(zip(body.name, body.position, strict=True)), "name")
        return _reply(loop.set_targets(world, values))
    except CommandError as exc:
        raise unprocessable(["body", *exc.field.split(".")], exc.message) from None


@router.post(
    "/targets",
    response_model=BatchCommandReply,
    summary="Full 7-joint targets for many worlds, applied together at one tick boundary",
)
async def post_targets(loop: Loop, body: BatchTargets) -> Response:
    n = loop.batch.nworld
    missing = [w for w in body.worlds if not 0 <= w < n]
    if missing:
        raise HTTPException(404, f"worlds {missing} do not exist (0..{n - 1})")
    results = loop.set_many(body.worlds, np.asarray(body.position, dtype=np.float64))
    return _json({"tick": results[0].tick, "results": [_reply_dict(r) for r in results]})


@router.post("/worlds/{world}/reset", response_model=ResetReply, summary="Reset one world to home")
async def reset_world(loop: Loop, world: World) -> ResetReply:
    return ResetReply(worlds=[world], tick=loop.reset([world]))


@router.post(
    "/reset", response_model=ResetReply, summary="Reset listed worlds (default: all) to home"
)
async def reset_many(loop: Loop, body: Annotated[ResetRequest | None, Body()] = None) -> ResetReply:
    n = loop.batch.nworld
    worlds = body.worlds if body is not None and body.worlds is not None else list(range(n))
    missing = [w for w in worlds if not 0 <= w < n]
    if missing:
        raise HTTPException(404, f"worlds {missing} do not exist (0..{n - 1})")
    return ResetReply(worlds=worlds, tick=loop.reset(worlds))
