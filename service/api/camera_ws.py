"""The camera stream: chosen worlds' images from one camera, at a chosen rate, over a WebSocket.

    /v1/ws/cameras?camera=wrist&worlds=0-15&rate=10&image=rgb&format=jpeg

Each binary message is one render of every listed world at one tick, laid out as
service/core/cameras/wire.py's `pack` (header JSON with `tick`, `worlds`, sizes; then the
images). Pictures are drawn at the instants of the rate's grid by one clock per camera and rate
(service/core/cameras/clock.py): every reader of that camera at that rate ready for a picture is
in the same render, and gets its own worlds of it. Newest only: the next picture is drawn
while the last one is being sent, and no other until that send is done, so a slow reader
holds its own drawing back instead of piling images up in the service (at most one message
waits beyond what the socket's buffers hold); a reader that keeps up gets `rate` a second
(fewer when drawing or sending takes longer than a period).
With `pull=true` nothing is in flight beyond what was asked: the client sends a text message
(any text) for each picture it wants, and gets the newest at that moment (still at most `rate`
a second).
Nothing is drawn while nobody is connected.

Under `armfleet serve` (uvicorn) the socket is taken over once accepted (service/api/ws_bulk.py):
messages are written by a thread of the socket's own, straight from the drawn pixels, so that
hundreds of megabytes a second cost the interpreter nothing; elsewhere they go through ASGI.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from typing import Annotated, Any

from fastapi import APIRouter, Query, WebSocket

from service.api import ws_bulk
from service.api.ws import flag, refuse
from service.api.ws_bulk import AsgiSocket, BulkSocket
from service.core.access import policy as access
from service.core.cameras import wire as camera_wire
from service.core.cameras.clock import Reader, clock_for
from service.core.cameras.feed import CameraFeed
from service.core.errors import ArmfleetError, BadCommand
from service.core.sim.worlds import parse_worlds

router = APIRouter(prefix="/v1")

MAX_RATE = 60.0  # images a second per socket


@router.websocket("/ws/cameras")
async def camera_socket(
    ws: WebSocket,
    camera: Annotated[
        str | None, Query(description="camera name, as GET /v1/cameras lists it")
    ] = None,
    worlds: Annotated[str, Query(description="e.g. 0-15,20")] = "0",
    rate: Annotated[str, Query(description=f"pictures a second, 0 < rate <= {MAX_RATE}")] = "10",
    image: Annotated[str, Query(description="rgb, depth or seg")] = "rgb",
    format: Annotated[str | None, Query(description="png, jpeg (rgb) or raw")] = None,
    quality: Annotated[str, Query(description="JPEG quality, 1..100")] = "80",
    pull: Annotated[str, Query(description="one picture per text message sent")] = "false",
) -> None:
    """Pictures of `camera` for `worlds`. Every query value is read here, after the handshake,
    so that a bad one closes the socket with 1008 and a reason naming it and its limit (a
    check in the route's signature would refuse the handshake itself, with a bare 403)."""
    runtime = ws.app.state.runtime
    grant = access.check_websocket(runtime.settings.access, ws)
    feed: CameraFeed | None = runtime.cameras
    if not grant.read:
        return await refuse(ws, grant, access.CLOSE_POLICY, grant.reason)
    if feed is None:
        return await refuse(ws, grant, access.CLOSE_TRY_AGAIN, "simulation is starting")
    try:
        if not camera:
            raise BadCommand("query.camera", "give the camera's name (GET /v1/cameras lists them)")
        hz = _number(rate, "query.rate", float, 0.0, MAX_RATE, above=True)
        quality_ = _number(quality, "query.quality", int, 1, 100)
        pull_ = flag(pull, "query.pull")
        fmt = camera_wire.choose(image, format, None)
        feed.want(camera, image)
        ids = parse_worlds(worlds, feed.loop.batch.nworld)
    except ArmfleetError as exc:
        return await refuse(ws, grant, access.CLOSE_POLICY, str(exc))
    await ws.accept(subprotocol=grant.subprotocol)
    link = ws_bulk.link(ws)  # at once after the accept: what the client sends next is the link's
    feed.streams_direct += link.direct
    feed.streams.add(link)
    reader = Reader(ids, pull_)
    clock = clock_for(feed, camera, hz)
    clock.join(reader)
    sender = asyncio.create_task(_send(link, reader, image, fmt, quality_))
    try:
        while (asked := await link.receive()) is not None:  # pulls; None: the client left
            if pull_ and isinstance(asked, str):  # a pull is any text message
                reader.ask()
                clock.poke()
    finally:
        clock.leave(reader)
        feed.streams.discard(link)
        sender.cancel()
        with contextlib.suppress(BaseException):
            await sender
        await link.finish()


def _number(
    text: str,
    field: str,
    kind: type[int] | type[float],
    low: float,
    high: float,
    above: bool = False,
) -> Any:
    """A query number, or BadCommand naming `field` and its range (`above`: `low` excluded)."""
    limits = f"{low:g} < value <= {high:g}" if above else f"{low:g} <= value <= {high:g}"
    try:
        value = kind(text)
    except ValueError:
        raise BadCommand(field, f"{text[:40]!r} is not a number ({limits})") from None
    if not math.isfinite(value) or value > high or (value <= low if above else value < low):
        raise BadCommand(field, f"{text[:40]} is out of range ({limits})")
    return value


async def _send(
    link: BulkSocket | AsgiSocket, reader: Reader, image: str, fmt: str, quality: int
) -> None:
    """Send each picture the clock draws for this reader (service/core/cameras/clock.py): the
    next one is drawn while this one is packed and sent, and none beyond it, so a slow reader
    holds back its own drawing and nothing piles up."""
    while True:
        try:
            shot = await reader.take()
        except ArmfleetError as exc:  # warming up: the clock tries again at its next instant
            if exc.status != 503:
                await link.close(access.CLOSE_POLICY, str(exc)[:120])
                return
            if reader.pull:
                reader.ask()  # still wanted
            continue
        message = await asyncio.to_thread(camera_wire.pack_parts, shot, image, fmt, quality)
        await link.send(message)  # waits while the reader is slow: nothing piles up
