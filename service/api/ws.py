"""WebSocket streams: state frames out, commands in, acks in order.

One socket = one Subscription. A reader task hands client messages to the control layer and
queues the acks it returns; a writer task sends acks first (never dropped, never reordered) and then
the newest state frame (older undelivered frames are replaced, so memory stays bounded).

Binary /v1/ws sockets (10 MB a frame at 65,536 worlds) are taken over once accepted, as the
camera streams are (service/api/ws_bulk.py): a thread of the socket's own writes each frame
straight from the frame thread's buffer, where the ASGI send copied it twice on the event
loop, holding the interpreter that the simulation loop needs.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter, Query, WebSocket, WebSocketDisconnect

from service.api import ws_bulk, ws_ops
from service.core.access import policy as access
from service.core.access import rates
from service.core.commands.base import BROWSER, WS
from service.core.commands.control import Control
from service.core.errors import ArmfleetError, BadCommand
from service.core.sim.command_share import cpu_now, turn
from service.core.sim.loop import SimLoop
from service.core.sim.types import Snapshot
from service.core.sim.worlds import parse_worlds
from service.core.streams import entity_frames, wire
from service.core.streams.formats import FrameFormat
from service.core.streams.hub import StreamHub, Subscription

router = APIRouter(prefix="/v1")

MAX_RATE = 1000.0
_MAX_QUEUED_ACKS = 256  # a client that never reads its acks stops being read (backpressure)


# The query values the state sockets share, declared once. `rate`: frames a second at most
# (default: one a tick); `worlds`: ids and inclusive ranges (parse_worlds); the default is the
# socket's own (all worlds; the focus world for /ws/view).
Rate = Annotated[float | None, Query(gt=0, le=MAX_RATE)]
Worlds = Annotated[str | None, Query(description="ids and ranges, e.g. 0-63 or 0,3,7")]
# `entities=true`: each frame carries the worlds' entities (service/core/streams/entity_frames.py).
Entities = Annotated[
    str | None,
    Query(description="true: each frame carries every entity's pose and twist"),
]


_TRUE, _FALSE = ("true", "1", "yes", "on"), ("false", "0", "no", "off")


def flag(value: str | None, field: str) -> bool:
    """A query flag as HTTP's routes read one (true/false, 1/0, yes/no, on/off); BadCommand
    naming `field` otherwise (FastAPI's own refusal on a socket names no field)."""
    if value is None or value.lower() in _FALSE:
        return False
    if value.lower() in _TRUE:
        return True
    raise BadCommand(field, f"{value[:40]!r} is not a flag: give true or false")


@router.websocket("/ws/worlds/{world}")
async def world_socket(
    ws: WebSocket,
    world: int,
    rate: Rate = None,
    entities: Entities = None,
) -> None:
    """One world's state frames (`{"op": "state", ...}`); commands need no `world` field."""

    def stream(loop: SimLoop, control: Control) -> Stream:
        shown, with_entities = control.world(world), flag(entities, "query.entities")
        names, brief = loop.spec.names, control.trajectories.brief

        def render(s: Snapshot) -> bytes:
            return wire.single_frame(s, shown, names, brief(shown), with_entities)

        fmt = FrameFormat.single(with_entities)
        return Stream(np.array([shown]), rate, fmt, render, default_world=shown)

    await _serve(ws, stream)


@router.websocket("/ws")
async def batch_socket(
    ws: WebSocket,
    worlds: Worlds = None,
    rate: Rate = None,
    format: Annotated[
        Literal["json", "binary"],
        Query(description="binary: float32 rows, see service/core/streams/wire.py"),
    ] = "json",
    entities: Entities = None,
) -> None:
    """Many worlds per frame (`{"op": "states", ...}`, column-wise); commands name `world`."""

    def stream(loop: SimLoop, control: Control) -> Stream:
        n, names = loop.batch.nworld, loop.spec.names
        ids = np.arange(n) if worlds is None else parse_worlds(worlds, n)
        with_entities = flag(entities, "query.entities")
        # Packed: the sim thread gathers these worlds' rows and a thread of the hub serialises
        # them (service.core.streams.frames); `render` makes the first frame, from a snapshot.
        if format == "binary":

            def render(s: Snapshot) -> bytes:
                return wire.batch_frame_binary(s, ids, names, with_entities)

            fmt = FrameFormat.batch_binary(tuple(names), with_entities)
            return Stream(ids, rate, fmt, render, direct=True)
        briefs = control.trajectories.briefs

        def render_json(s: Snapshot) -> bytes:
            return wire.batch_frame(s, ids, names, briefs(ids), with_entities)

        return Stream(ids, rate, FrameFormat.batch(tuple(names), with_entities), render_json)

    await _serve(ws, stream)


class StillFilter:
    """Drops a view socket's frame when nothing it shows changed (poses, targets, faults) since
    the last frame sent, except one every HEARTBEAT_S (tick and speed for the status line).

    A page watching resting arms then wakes twice a second instead of thirty times: most of a
    still viewer's cost, in the browser and in the server. Any motion, command or fault sends
    at once. Per socket state, used on the event loop only.
    """

    HEARTBEAT_S = 0.5
    STILL = 1e-4  # m or quaternion units: below what a page draws differently

    def __init__(self, worlds: np.ndarray) -> None:
        self.worlds = worlds
        self.sent: tuple[np.ndarray, ...] | None = None
        self.sent_at = 0.0

    def __call__(self, snap: Snapshot) -> bool:
        w, now = self.worlds, time.monotonic()
        state = (snap.body_pos[w], snap.body_quat[w], snap.target[w], snap.faults[w])
        if self.sent is not None and now - self.sent_at < self.HEARTBEAT_S:
            pos, quat, target, faults = self.sent
            if (
                np.array_equal(state[2], target)
                and np.array_equal(state[3], faults)
                and np.abs(state[0] - pos).max() < self.STILL
                and np.abs(state[1] - quat).max() < self.STILL
            ):
                return True
        self.sent, self.sent_at = state, now
        return False


MAX_VIEW_WORLDS = 256  # what the page's fleet view draws; ~136 KB per pose frame


@router.websocket("/ws/view")
async def view_socket(
    ws: WebSocket,
    worlds: Worlds = None,
    focus: Annotated[int | None, Query(description="world whose joint state rides along")] = None,
    rate: Rate = None,
) -> None:
    """The browser page's socket: binary pose frames (`core/wire.py`), commands name `world`.

    Each frame carries every body's pose for `worlds` (default: the focus world) and the `focus`
    world's joint state in its header, so one socket feeds both the 3D view and the panel. Its
    commands are the control layer's with source `browser`.
    """

    def stream(loop: SimLoop, control: Control) -> Stream:
        shown = None if focus is None else control.world(focus)
        if worlds is not None:
            ids = parse_worlds(worlds, loop.batch.nworld)
        elif shown is not None:
            ids = np.array([shown])
        else:
            raise BadCommand("query.worlds", "give `worlds`, `focus` or both")
        if len(ids) > MAX_VIEW_WORLDS:
            raise BadCommand("query.worlds", f"{len(ids)} asked, at most {MAX_VIEW_WORLDS}")
        names = loop.spec.names

        def render(snap: Snapshot) -> bytes:
            st = loop.stats
            stats = {
                "mode": st.mode.value,
                "ticks_per_s": st.ticks_per_s,
                "realtime_factor": st.realtime_factor,
                "trajectory": None if shown is None else control.trajectories.brief(shown),
            }
            return wire.pose_frame(snap, ids, names, shown, stats)

        fmt = FrameFormat.view(shown)
        return Stream(ids, rate, fmt, render, skip=StillFilter(ids), source=BROWSER)

    await _serve(ws, stream)


@dataclass(frozen=True)
class Stream:
    """What one socket streams, read from its query: the worlds, the rate, the frame format
    and the renderer of a frame from a snapshot; `skip` drops frames (the page's: nothing
    moved), `default_world` is the world commands without `world` go to, `source` the
    commands' source."""

    worlds: np.ndarray
    rate: float | None
    format: FrameFormat
    render: Callable[[Snapshot], bytes]
    skip: Callable[[Snapshot], bool] | None = None
    default_world: int | None = None
    source: str = WS
    direct: bool = False


async def refuse(ws: WebSocket, grant: access.Grant, code: int, reason: str) -> None:
    """Turn a socket away that cannot be served (every WebSocket route here): accepted first,
    with the subprotocol its token came in, so that the client reads `code` and `reason`
    (clipped: a close frame holds 123 bytes) instead of a bare handshake failure."""
    await ws.accept(subprotocol=grant.subprotocol)
    await ws.close(code=code, reason=reason[:120])


def _grant(ws: WebSocket) -> access.Grant:
    runtime = ws.app.state.runtime
    return access.check_websocket(runtime.settings.access, ws, runtime.leases)


async def _serve(ws: WebSocket, read: Callable[[SimLoop, Control], Stream]) -> None:
    """Serve one socket: `read` reads its query into a `Stream` (an ArmfleetError closes the
    socket with 1008 naming the field; 1013 while the service starts), then its Subscription,
    built whole here with the socket's closer, streams, and its commands are run."""
    runtime = ws.app.state.runtime
    loop, control, hub = runtime.loop, runtime.control, runtime.hub
    if loop is None or control is None or hub is None:
        return await refuse(ws, _grant(ws), access.CLOSE_TRY_AGAIN, "simulation is starting")
    try:
        stream = read(loop, control)
    except ArmfleetError as exc:
        return await refuse(ws, _grant(ws), access.CLOSE_POLICY, str(exc))
    default_world, source = stream.default_world, stream.source
    grant = _grant(ws)
    limiter = rates.RateLimiter(
        runtime.settings.access.command_rate, runtime.settings.access.command_burst
    )
    metrics, share = runtime.metrics, loop.share
    control = control.acting_for(grant.caller)  # each command checked for its worlds
    await ws.accept(subprotocol=grant.subprotocol)
    # At once after the accept (no await between): what the client sends next is the link's.
    link = ws_bulk.link(ws, max_incoming=None) if stream.direct else ws_bulk.AsgiSocket(ws)
    hub.streams_direct += link.direct

    async def close(code: int, reason: str) -> None:
        await link.close(code=code, reason=reason[:120])

    sub = Subscription(
        stream.worlds, stream.rate, stream.format, stream.render, skip=stream.skip, close=close
    )
    first = loop.latest
    if sub.entities and first.entities is None:  # nobody asked before: read them at a boundary
        first = await asyncio.wrap_future(loop.call(entity_frames.snapshot_with_entities))
    hub.add(sub)
    sub.offer(first, time.monotonic())  # the current state at once, then the stream
    writer = asyncio.create_task(_write(link, hub, sub))
    busy_until = 0.0  # refused as busy: until then, what cannot run at once is refused at once
    try:
        while True:
            message = await link.receive()
            if message is None:  # the client left
                break
            while len(sub.acks) > _MAX_QUEUED_ACKS:
                await asyncio.sleep(0.005)
            text = message if isinstance(message, str) else None
            if text is None:
                reply = wire.error_frame(None, "send JSON as text frames")
                metrics.command_rejected(source, "unknown")
            elif not grant.command:
                reply = wire.error_frame(wire.read_id(text), grant.reason)
                metrics.command_rejected(source, "unknown", "refused")
            else:
                verdict = limiter.take()
                if verdict == "ok" and not await turn(share, time.monotonic() > busy_until):
                    busy_until = time.monotonic() + share.max_wait_s  # ticks first: busy
                    reply = wire.error_frame(wire.read_id(text), share.busy_detail)
                    metrics.command_rejected(source, ws_ops.kind_of(text), "refused")
                elif verdict == "ok":
                    t0 = cpu_now()
                    reply, kind = ws_ops.handle_text(control, text, default_world, source)
                    share.spent(cpu_now() - t0)
                    if reply.get("op") == "error":
                        metrics.command_rejected(source, kind)
                    elif reply.get("op") == "ack" and isinstance(reply.get("tick"), int):
                        sub.owe(reply["tick"])  # its first frame goes out whatever the cadence
                else:
                    reply = wire.error_frame(wire.read_id(text), limiter.detail)
                    metrics.command_rejected(source, ws_ops.kind_of(text), "refused")
                    if verdict == "close":
                        sub.push_ack(wire.dumps(reply))
                        await _drain(sub)
                        await close(access.CLOSE_POLICY, "over the command rate")
                        break
            sub.push_ack(wire.dumps(reply))
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        hub.remove(sub)
        writer.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await writer
        await link.finish()


async def _write(
    link: ws_bulk.BulkSocket | ws_bulk.AsgiSocket, hub: StreamHub, sub: Subscription
) -> None:
    while True:
        await sub.ready.wait()
        sub.ready.clear()
        while sub.acks:  # all that wait, in one write where the socket is taken over
            await link.send_texts([sub.acks.popleft() for _ in range(len(sub.acks))])
        frame, sub.frame = sub.frame, None  # packed and serialised off the loop
        snap, sub.latest = sub.latest, None
        if frame is None:
            if snap is None or (sub.skip is not None and sub.skip(snap)):
                continue
            frame = hub.frame(sub, snap)
        if sub.binary:
            await link.send([frame])
        else:
            await link.send_texts([frame])


async def _drain(sub: Subscription, timeout: float = 1.0) -> None:
    """Give the writer a moment to send what is queued (the last error) before closing."""
    deadline = time.monotonic() + timeout
    while sub.acks and time.monotonic() < deadline:
        await asyncio.sleep(0.01)
