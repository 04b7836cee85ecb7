"""The browser page: `GET /` serves it, `/web/...` its scripts and the vendored three.js.

The files live inside the package (service/web/, shipped as package data) so that the page is
found the same way from a checkout and from an installed wheel, and works with no internet.
`GET /` is an ordinary route on purpose: a WebSocket route may share the path (rosbridge).
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

WEB_DIR = Path(__file__).resolve().parents[1] / "web"

router = APIRouter(tags=["page"])


@router.get("/", include_in_schema=False)
async def page() -> FileResponse:
    # no-cache: the page is tiny and must match the scripts of the running version.
    return FileResponse(WEB_DIR / "index.html", headers={"Cache-Control": "no-cache"})


def mount_static(app: FastAPI) -> None:
    """/web/...: the page's modules and vendored libraries (routers cannot carry mounts)."""
    app.mount("/web", StaticFiles(directory=WEB_DIR), name="web")
