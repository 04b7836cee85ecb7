"""The FastAPI application: routers, lifespan, body-size limit and error shapes."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import AsyncIterator
from typing import Any

from fastapi import FastAPI, HTTPException, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import compile_path
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from mjcf import SCENE_XML
from service.api import (
    camera_ws,
    cameras,
    cartesian,
    health,
    info,
    leases,
    metrics,
    recordings,
    scene,
    sim,
    snapshots,
    trajectory,
    web,
    worlds,
    ws,
    ws_bulk,
)
from service.api.turns import TakeTurns
from service.core.access import policy as access
from service.core.contract.cell import fit_cell
from service.core.contract.replies import ANY, errors, fit_openapi
from service.core.errors import ArmfleetError, BadCommand
from service.core.metrics import CommandCounter
from service.core.sim.robot import LoadedRobot, load_robot
from service.runtime import Runtime
from service.settings import Settings

DESCRIPTION = """
Many simulated UR10e + Robotiq 2F-140 worlds stepped together by MuJoCo Warp.
Commands (increments, JointState-shaped targets, resets) are applied at the next control-tick
boundary, all or nothing; every reply says at which `tick` it takes effect.

WebSocket streams (not listed by OpenAPI):
* `/v1/ws/worlds/{world}?rate=30`: `{"op": "state", ...}` frames with the fields of
  `GET /v1/worlds/{world}/state`; send `{"op": "increment", "joint": "elbow_joint",
  "delta": 0.1, "id": 1}`, `{"op": "set_targets", "name": [...], "position": [...], "id": 2}`
  or `{"op": "reset", "id": 3}`; replies `{"op": "ack", "id", "tick", "target", "clamped"}` or
  `{"op": "error", "id", "detail"}`.
* `/v1/ws?worlds=0-63&rate=10`: `{"op": "states", ...}` frames, column-wise over the listed
  worlds; commands carry `"world"`.
* `/v1/ws/view?worlds=0-63&focus=3&rate=30`: the browser page's socket: binary pose frames
  (every body of every listed world, plus the focus world's state; layout in
  service/core/streams/wire.py)
  drawn with the geoms of `GET /v1/scene`; commands carry `"world"`.

* `/v1/ws/cameras?camera=wrist&worlds=0-15&rate=10&format=jpeg`: binary messages of camera
  images, one render of the listed worlds at one tick each (layout in service/core/cameras/wire.py;
  `pull=true`: one per text message sent).

Leases (`armfleet serve --leases optional|required`): `POST /v1/leases` lends worlds with a
token of their own, which commands those worlds only, here and on every socket (403 naming any
other world); see docs/guides/leases.md.

The browser page is served at `/` (`/?lease=<token>`: a lease's worlds only).
"""


class BodySizeLimit:
    """413 for request bodies over the limit, whether or not Content-Length is sent."""

    def __init__(self, app: ASGIApp, max_bytes: int):
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        too_large = HTTPException(413, f"request body over the limit of {self.max_bytes} bytes")
        length = dict(scope["headers"]).get(b"content-length")
        if length is not None and length.isdigit() and int(length) > self.max_bytes:
            response = JSONResponse({"detail": too_large.detail}, status_code=413)
            return await response(scope, receive, send)
        seen = 0

        async def limited() -> Message:
            nonlocal seen
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > self.max_bytes:
                raise too_large
            return message

        await self.app(scope, limited, send)


async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
    # FastAPI's default echoes the offending input, which may be NaN and unserialisable.
    detail = [{"loc": list(e["loc"]), "msg": e["msg"], "type": e["type"]} for e in exc.errors()]
    return JSONResponse({"detail": detail}, status_code=422)


async def _http_error(request: Request, exc: Exception) -> Response:
    """FastAPI's own handling, except that a 405 lists every method the path takes.

    (Starlette's lists only those of the first route whose path matched, when GET and POST of
    one path are separate routes, as in /v1/snapshots.)
    """
    assert isinstance(exc, StarletteHTTPException)
    if exc.status_code == 405:
        allowed = await asyncio.to_thread(_methods_of, request.app, request.url.path)
        if allowed:
            exc.headers = {**(exc.headers or {}), "Allow": ", ".join(allowed)}
    return await http_exception_handler(request, exc)


def _methods_of(app: FastAPI, path: str) -> list[str]:
    """Every method the OpenAPI description lists for `path` (HEAD with GET). Run on a thread:
    the first call may build the document (seconds of CPU)."""
    found: set[str] = set()
    for template, operations in app.openapi().get("paths", {}).items():
        if compile_path(template)[0].match(path):
            found.update(m.upper() for m in operations if m != "parameters")
    if "GET" in found:
        found.add("HEAD")
    return sorted(found)


async def _armfleet_error(request: Request, exc: Exception) -> JSONResponse:
    """The one mapping of domain errors to HTTP: status from the class, detail from the error."""
    assert isinstance(exc, ArmfleetError)
    if isinstance(exc, BadCommand):
        # Shaped like FastAPI's own validation errors, so clients parse one 422 format.
        loc = (exc.field or "body").split(".")
        if loc[0] not in ("body", "query", "path"):
            loc = ["body", *loc]
        detail: object = [{"loc": loc, "msg": exc.message, "type": "value_error"}]
    else:
        detail = exc.detail
    headers = {"Retry-After": "2"} if exc.status == 503 else None
    return JSONResponse({"detail": detail}, status_code=exc.status, headers=headers)


def create_app(settings: Settings | None = None) -> FastAPI:
    """The service as an ASGI app; ValueError when the settings are unsafe (see access)."""
    settings = settings or Settings()
    access.check_bind(settings.server.host, settings.access)
    runtime = Runtime(settings)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        starting = asyncio.create_task(runtime.start())
        yield
        with contextlib.suppress(BaseException):
            await asyncio.wait_for(starting, timeout=120)
        runtime.stop()

    app = FastAPI(
        title="armfleet",
        version="0.1.0",
        description=DESCRIPTION,
        lifespan=lifespan,
        exception_handlers={
            RequestValidationError: _validation_error,
            StarletteHTTPException: _http_error,
            ArmfleetError: _armfleet_error,
        },
    )
    app.state.runtime = runtime
    app.add_middleware(BodySizeLimit, max_bytes=settings.server.max_body_bytes)
    app.add_middleware(TakeTurns)  # ticks first: commands wait for the tick's budget
    # Added last = runs first: count refused commands, then check token, origin and slots.
    app.add_middleware(
        access.AccessMiddleware,
        settings=settings.access,
        slots=runtime.slots,
        leases=lambda: runtime.leases,
    )
    app.add_middleware(CommandCounter, metrics=runtime.metrics)
    app.add_middleware(ws_bulk.RememberOwner)  # outermost: sees the server's own `send`
    for module in (health, metrics, web):
        app.include_router(module.router)
    for router in runtime.surfaces.routers():  # rosbridge's socket and GET /v1/ros
        app.include_router(router)
    # Every /v1 route can also answer 401/403 (token, origin) and 503 (not ready, client cap).
    for module in (
        info,
        worlds,
        cartesian,
        trajectory,
        sim,
        scene,
        ws,
        snapshots,
        recordings,
        cameras,
        camera_ws,
        leases,
    ):
        app.include_router(module.router, responses=errors(*ANY))
    web.mount_static(app)
    generate = app.openapi

    def served() -> LoadedRobot:
        """The served cell: the running engine's, or (before it runs) the scene compiled."""
        loop = runtime.loop
        return loop.batch.robot if loop is not None else load_robot(settings.sim.scene or SCENE_XML)

    building = threading.Lock()  # one build: a second request waits for the first's

    def openapi() -> dict[str, Any]:
        with building:
            if app.openapi_schema is None:
                robot = served()
                spec = fit_openapi(generate(), settings.sim.worlds)
                app.openapi_schema = fit_cell(spec, robot.mjm, robot.spec.names)
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    _document_off_the_loop(app)
    return app


def _document_off_the_loop(app: FastAPI) -> None:
    """GET /openapi.json builds (once) and renders the document on a thread.

    It takes seconds of CPU on a busy box: FastAPI's own route builds it on the event loop, and
    the first request for it held every other request that long (schemathesis timed out loading
    it under a fuzz run's load). Built when first asked, not at start: most servers are never
    asked, and each start paid for it.
    """
    url = app.openapi_url
    routes = app.router.routes
    (fastapis,) = [i for i, route in enumerate(routes) if getattr(route, "path", None) == url]
    del routes[fastapis]  # (the docs pages stay FastAPI's; they read the document at `url`)

    async def document(request: Request) -> Response:
        return await asyncio.to_thread(lambda: JSONResponse(app.openapi()))

    app.add_route(url, document, include_in_schema=False)
