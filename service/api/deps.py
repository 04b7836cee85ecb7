"""Dependencies shared by the routers: the runtime, the loop, the control layer, world ids.

They are `async def` on purpose: plain `def` dependencies each hop through the threadpool
(~0.1 ms apiece on every request). Errors are raised as service.core.errors exceptions; the app maps
them to status codes in one place.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Depends, Path, Request

from service.core.commands.control import Control
from service.core.contract.replies import ErrorReply, answers
from service.core.errors import Unavailable
from service.core.sim import rules
from service.core.sim.loop import SimLoop
from service.persistence.snapshots import check_state_support
from service.runtime import Runtime


async def get_runtime(request: Request) -> Runtime:
    return request.app.state.runtime


async def get_loop(runtime: Annotated[Runtime, Depends(get_runtime)]) -> SimLoop:
    if runtime.loop is None:
        starting = "simulation is starting (compiling kernels); see /readyz"
        raise Unavailable(runtime.error or starting)
    return runtime.loop


async def get_control(
    request: Request,
    runtime: Annotated[Runtime, Depends(get_runtime)],
    loop: Annotated[SimLoop, Depends(get_loop)],
) -> Control:
    """Control acting for the request's caller (AccessMiddleware found it): every command a
    route runs is checked against the worlds that caller may command."""
    assert runtime.control is not None  # set together with the loop
    return runtime.control.acting_for(getattr(request.state, "caller", None))


Loop = Annotated[SimLoop, Depends(get_loop)]
Ctl = Annotated[Control, Depends(get_control)]
Rt = Annotated[Runtime, Depends(get_runtime)]


async def get_state_loop(loop: Loop) -> SimLoop:
    """The loop, for a route that saves or restores the full state (snapshots, recordings):
    Conflict (409) naming the engine when it cannot, before the route does anything."""
    check_state_support(loop.batch)
    return loop


StateLoop = Annotated[SimLoop, Depends(get_state_loop)]


WorldPath = Annotated[int, Path(description="world index")]


async def world_id(loop: Loop, world: WorldPath) -> int:
    return rules.world_id(world, loop.batch.nworld)


World = Annotated[int, Depends(world_id)]  # routes that read a world
# Routes that run a command take the id as it came: the command checks it, once.
CommandWorld = WorldPath


def moves_arm(reply: Any) -> dict[str, Any]:
    """The answers of a route that moves the arm (targets, jogs, trajectories), for its
    decorator (`**moves_arm(reply)`): `reply`, or 409 while the world is protective-stopped
    (core/sim/safety.py), until the stop is unlocked or the world reset."""
    return answers(reply, 409)


# `responses=` of routes that write a file (snapshots, recordings): the domain error CannotWrite.
CANNOT_WRITE: dict[int | str, dict[str, Any]] = {
    507: {
        "model": ErrorReply,
        "description": "the file cannot be written (disk full, read-only folder, a FIFO nobody "
        "reads): the detail names the path and the cause; nothing was replaced",
    }
}


def writes_file(reply: Any, others: dict[int | str, dict[str, Any]]) -> dict[str, Any]:
    """The answers of a route that creates a file (a snapshot, a recording), for its decorator
    (`**writes_file(reply, others)`): 201 with `reply`, 507 when the file cannot be written,
    and the `others` the route can answer."""
    return {"response_model": reply, "status_code": 201, "responses": {**CANNOT_WRITE, **others}}
