"""Trajectory routes: start one world's (POST), watch it (GET, optionally waiting for the
outcome), cancel and hold (DELETE), and start one trajectory on many worlds at one tick.

Validation is `service.trajectory.parse` (422 naming the field and the limit, nothing changed);
running it is `Control.start_trajectory`, as for every other surface.
"""

from __future__ import annotations

import asyncio
from typing import Annotated

import numpy as np
from fastapi import APIRouter, Query
from fastapi.responses import Response

from service.api.answers import json_reply
from service.api.deps import CommandWorld, Ctl, World, moves_arm
from service.core.commands.base import HTTP
from service.core.commands.control import Control
from service.core.commands.trajectory import TrajectoryStatus, parse
from service.core.commands.trajectory.schemas import (
    BatchStartedReply,
    BatchTrajectoryBody,
    StartedReply,
    TrajectoryBody,
    TrajectoryStatusReply,
)
from service.core.contract.replies import answers, errors
from service.core.errors import BadCommand, Conflict, NotFound
from service.core.sim.worlds import parse_worlds

# Every route here names worlds, so each can answer 404 for an unknown one.
router = APIRouter(prefix="/v1", tags=["trajectories"], responses=errors(404))
MAX_WAIT_S = 60.0


@router.post(
    "/worlds/{world}/trajectory",
    summary="Follow a JointTrajectory (replaces a running one); answers its id and ticks",
    **moves_arm(StartedReply),
)
async def start(control: Ctl, world: CommandWorld, body: TrajectoryBody) -> Response:
    spec = parse(control.spec, body.as_json())
    started = control.start_trajectory([world], spec, HTTP)[0]
    return json_reply(started.as_json())


Wait = Annotated[
    float,
    Query(
        ge=0,
        le=MAX_WAIT_S,
        allow_inf_nan=False,
        description="seconds to wait for a running trajectory's outcome before answering",
    ),
]


@router.get(
    "/worlds/{world}/trajectory",
    response_model=TrajectoryStatusReply,
    summary="Status, progress and feedback of the world's running (else last) trajectory",
)
async def status(control: Ctl, world: World, wait: Wait = 0.0) -> Response:
    missing = NotFound(f"world {world} has not run a trajectory", "world")
    return await _answer(control, control.trajectories.status(world), wait, missing)


@router.get(
    "/trajectories/{trajectory_id}",
    response_model=TrajectoryStatusReply,
    summary="One trajectory by id (also after a newer one replaced it on its world)",
)
async def by_id(control: Ctl, trajectory_id: int, wait: Wait = 0.0) -> Response:
    missing = NotFound(f"no trajectory {trajectory_id} (unknown, or long forgotten)", "id")
    return await _answer(control, control.trajectories.get(trajectory_id), wait, missing)


async def _answer(
    control: Control, current: TrajectoryStatus | None, wait: float, missing: NotFound
) -> Response:
    """The status reply (after waiting up to `wait` for the outcome), or `missing` (404)."""
    if current is None:
        raise missing
    return json_reply((await _outcome(control, current, wait)).as_json())


async def _outcome(control: Control, current: TrajectoryStatus, wait: float) -> TrajectoryStatus:
    """`current`, or its final status if it comes within `wait` seconds."""
    if wait <= 0 or current.done:
        return current
    fut = control.trajectories.wait(current.id)
    try:
        return await asyncio.wait_for(asyncio.wrap_future(fut), timeout=wait)
    except TimeoutError:
        return control.trajectories.get(current.id) or current


@router.delete(
    "/worlds/{world}/trajectory",
    summary="Cancel the world's running trajectory; the world holds where it was",
    **answers(TrajectoryStatusReply, 409),
)
async def cancel(control: Ctl, world: CommandWorld) -> Response:
    stopped = control.cancel_trajectory([world], HTTP)
    if not stopped:
        raise Conflict(f"world {world} runs no trajectory", "world")
    return json_reply(stopped[0].as_json())


@router.post(
    "/trajectories",
    summary="Start one trajectory on many worlds, all at the same tick",
    **moves_arm(BatchStartedReply),
)
async def start_many(control: Ctl, body: BatchTrajectoryBody) -> Response:
    worlds = _worlds(control, body.worlds)
    spec = parse(control.spec, body.trajectory.as_json())
    started = control.start_trajectory(worlds, spec, HTTP)
    return json_reply(
        {
            "start_tick": started[0].start_tick,
            "end_tick": started[0].end_tick,
            "started": len(started),
            "ids": np.array([s.id for s in started], dtype=np.int64),
            "worlds": np.array(worlds, dtype=np.int64),
        }
    )


def _worlds(control: Control, worlds: list[int] | str) -> list[int]:
    if isinstance(worlds, str):
        return parse_worlds(worlds, control.nworld).tolist()
    ids = control.worlds(worlds)  # unknown ids are named first (404), then a repeat (422)
    if len(set(ids)) != len(ids):
        raise BadCommand("worlds", "a world may be listed only once")
    return ids
