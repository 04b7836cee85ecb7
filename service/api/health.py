"""Liveness and readiness (outside /v1: orchestration probes, not API)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse

from service.api.deps import get_runtime
from service.runtime import Runtime

router = APIRouter(tags=["health"])


@router.get("/healthz", summary="The process is alive")
async def healthz() -> dict[str, str]:
    return {"status": "ok"}


@router.get(
    "/readyz",
    summary="Kernels compiled and the control tick captured: ready for commands",
    responses={503: {"description": "still starting, or the engine failed (see detail)"}},
)
async def readyz(runtime: Annotated[Runtime, Depends(get_runtime)]) -> JSONResponse:
    if runtime.loop is not None:
        return JSONResponse({"status": "ready", "tick": runtime.loop.latest.tick})
    status = "failed" if runtime.error else "starting"
    return JSONResponse({"status": status, "detail": runtime.error}, status_code=503)
