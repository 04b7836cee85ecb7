"""GET /v1/scene: what to draw, from the compiled model (see service/core/scene.py)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import Response

from service.api.deps import Loop
from service.core import scene, wire
from service.core.scene_schemas import Scene

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
