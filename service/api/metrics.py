"""GET /metrics: Prometheus text format (see service/core/metrics.py for what is counted)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends
from fastapi.responses import Response

from service.api.deps import get_runtime
from service.core.metrics import CONTENT_TYPE
from service.runtime import Runtime

router = APIRouter(tags=["health"])


@router.get(
    "/metrics",
    summary="Prometheus metrics: ticks, tick time, real-time factor, commands, latency, faults",
    response_class=Response,
    responses={200: {"content": {CONTENT_TYPE.split(";")[0]: {"schema": {"type": "string"}}}}},
)
async def metrics(runtime: Annotated[Runtime, Depends(get_runtime)]) -> Response:
    return Response(runtime.metrics.render(), media_type=CONTENT_TYPE)
