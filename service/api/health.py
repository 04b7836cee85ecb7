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
    responses={
        503: {
            "description": "starting, the engine failed, ticks are failing or a shard worker "
            "was lost and is being rebuilt (`problems` says which)"
        }
    },
)
async def readyz(runtime: Annotated[Runtime, Depends(get_runtime)]) -> JSONResponse:
    problems = runtime.problems()
    if runtime.loop is not None and not problems:
        return JSONResponse({"status": "ready", "tick": runtime.loop.latest.tick})
    status = "degraded"  # running, but a tick is failing or a shard is being rebuilt
    if runtime.loop is None:
        status = "failed" if runtime.error else "starting"
    detail = "; ".join(problems)
    return JSONResponse({"status": status, "detail": detail, "problems": problems}, status_code=503)
