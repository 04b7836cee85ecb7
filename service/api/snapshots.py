"""Snapshots: save every world's full state to a file, list them, restore one at a tick boundary."""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, Path

from service.api.deps import Rt, StateLoop, writes_file
from service.core.contract.snapshots import (
    RestoreReply,
    SnapshotInfo,
    SnapshotName,
    SnapshotRequest,
)
from service.core.errors import Conflict

router = APIRouter(prefix="/v1/snapshots", tags=["snapshots"])


@router.post(
    "",
    summary="Save the full state of every world as snapshot `name` (replaces one of that name)",
    **writes_file(
        SnapshotInfo, {422: {"description": "bad name (separators, empty, over 64 characters)"}}
    ),
)
async def save(runtime: Rt, loop: StateLoop, body: SnapshotRequest) -> SnapshotInfo:
    state = await asyncio.wrap_future(loop.state_door.request_state())
    info = await asyncio.to_thread(
        runtime.persistence.snapshots.save, body.name, state, runtime.header
    )
    return info


@router.get("", response_model=list[SnapshotInfo], summary="Saved snapshots, newest first")
async def listing(runtime: Rt) -> list[SnapshotInfo]:
    infos = await asyncio.to_thread(runtime.persistence.snapshots.list)
    return infos


@router.post(
    "/{name}/restore",
    response_model=RestoreReply,
    summary="Continue every world from snapshot `name`, at the next tick boundary",
    responses={
        404: {"description": "no snapshot of that name"},
        409: {"description": "another model or number of worlds, or a truncated/corrupt file"},
        422: {"description": "bad name"},
    },
)
async def restore(
    runtime: Rt, loop: StateLoop, name: Annotated[SnapshotName, Path()]
) -> RestoreReply:
    # Read and check the whole file first: a bad one changes nothing.
    state = await asyncio.to_thread(runtime.persistence.snapshots.load, name, runtime.header)
    try:
        tick = await asyncio.wrap_future(loop.state_door.restore(state, name))
    except ValueError as exc:
        raise Conflict(f"cannot restore snapshot {name!r}: {exc}") from None
    return RestoreReply(name=name, tick=tick)
