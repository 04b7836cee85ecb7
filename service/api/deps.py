"""Dependencies shared by the routers: the running loop, world ids, and error shapes.

They are `async def` on purpose: plain `def` dependencies each hop through the threadpool
(~0.1 ms apiece on every request).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request

from service.loop import SimLoop
from service.runtime import Runtime


async def get_runtime(request: Request) -> Runtime:
    return request.app.state.runtime


async def get_loop(runtime: Annotated[Runtime, Depends(get_runtime)]) -> SimLoop:
    if runtime.loop is None:
        detail = runtime.error or "simulation is starting (compiling kernels); see /readyz"
        raise HTTPException(status_code=503, detail=detail, headers={"Retry-After": "2"})
    return runtime.loop


Loop = Annotated[SimLoop, Depends(get_loop)]


async def world_id(loop: Loop, world: Annotated[int, Path(description="world index")]) -> int:
    if not 0 <= world < loop.batch.nworld:
        raise HTTPException(404, f"world {world} does not exist (0..{loop.batch.nworld - 1})")
    return world


World = Annotated[int, Depends(world_id)]


def unprocessable(loc: list[str | int], message: str) -> HTTPException:
    """A 422 shaped like FastAPI's own validation errors, so clients parse one format."""
    return HTTPException(422, [{"loc": loc, "msg": message, "type": "value_error"}])
