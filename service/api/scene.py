"""GET /v1/scene: what to draw, from the compiled model (see service/core/sim/scene.py)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import Response

from service.api.deps import Loop
from service.core.contract.scene import Scene
from service.core.sim import scene
from service.core.streams import wire

router = APIRouter(prefix="/v1", tags=["scene"])


@router.get(
    "/scene",
    response_model=Scene,
    summary="Bodies and visible geoms as MuJoCo compiled them (the page's 3D scene)",
)
async def get_scene(loop: Loop, request: Request) -> Response:
    # The model never changes while the service runs: describe it once per app.
    body = getattr(request.app.state, "scene_json", None)
    if body is None:
        body = request.app.state.scene_json = wire.dumps(scene.describe(loop.batch.robot.mjm))
    return Response(body, media_type="application/json")
