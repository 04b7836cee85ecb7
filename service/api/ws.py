"""WebSocket streams: state frames out, commands in, acks in order.

One socket = one Subscription. A reader task turns client messages into loop commands and
queues their acks; a writer task sends acks first (never dropped, never reordered) and then
the newest state frame (older undelivered frames are replaced, so memory stays bounded).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from typing import Annotated, Any, Literal

import numpy as np
import orjson
from fastapi import APIRouter, Query, WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from service import wire
from service.commands import CommandError, resolve_joints
from service.hub import StreamHub, Subscription
from service.loop import SimLoop
from service.schemas import IncrementRequest, JointTargets
from service.types import Snapshot

router = APIRouter(prefix="/v1")

MAX_RATE = 1000.0
_MAX_QUEUED_ACKS = 256  # a client that never reads its acks stops being read (backpressure)
_CLOSE_TRY_AGAIN = 1013
_CLOSE_POLICY = 1008


@router.websocket("/ws/worlds/{world}")
async def world_socket(
    ws: WebSocket,
    world: int,
    rate: Annotated[float | None, Query(gt=0, le=MAX_RATE)] = None,
) -> None:
    """One world's state frames (`{"op": "state", ...}`); commands need no `world` field."""
    loop, hub = _running(ws)
    if loop is None or hub is None:
        return await _refuse(ws, _CLOSE_TRY_AGAIN, "simulation is starting")
    if not 0 <= world < loop.batch.nworld:
        return await _refuse(ws, _CLOSE_POLICY, f"world {world} does not exist")
    names = loop.spec.names
    sub = Subscription(
        np.array([world]), rate, lambda s: wire.single_frame(s, world, names), "single"
    )
    await _serve(ws, loop, hub, sub, default_world=world)


@router.websocket("/ws")
async def batch_socket(
    ws: WebSocket,
    worlds: Annotated[str | None, Query(description="e.g. 0-63 or 0,3,7 (default all)")] = None,
    rate: Annotated[float | None, Query(gt=0, le=MAX_RATE)] = None,
    format: Annotated[
        Literal["json", "binary"], Query(description="binary: float32 rows, see service/wire.py")
    ] = "json",
) -> None:
    """Many worlds per frame (`{"op": "states", ...}`, column-wise); commands name `world`."""
    loop, hub = _running(ws)
    if loop is None or hub is None:
        return await _refuse(ws, _CLOSE_TRY_AGAIN, "simulation is starting")
    try:
        ids = (
            np.arange(loop.batch.nworld)
            if worlds is None
            else wire.parse_worlds(worlds, loop.batch.nworld)
        )
    except (ValueError, IndexError) as exc:
        return await _refuse(ws, _CLOSE_POLICY, str(exc))
    names = loop.spec.names
    if format == "binary":
        sub = Subscription(
            ids, rate, lambda s: wire.batch_frame_binary(s, ids, names), "binary", binary=True
        )
    else:
        sub = Subscription(ids, rate, lambda s: wire.batch_frame(s, ids, names), "batch")
    await _serve(ws, loop, hub, sub, default_world=None)


MAX_VIEW_WORLDS = 256  # what the page's fleet view draws; ~136 KB per pose frame


@router.websocket("/ws/view")
async def view_socket(
    ws: WebSocket,
    worlds: Annotated[
        str | None, Query(description="worlds whose body poses to send, e.g. 0-63 (default: focus)")
    ] = None,
    focus: Annotated[int | None, Query(description="world whose joint state rides along")] = None,
    rate: Annotated[float | None, Query(gt=0, le=MAX_RATE)] = None,
) -> None:
    """The browser page's socket: binary pose frames (`service/wire.py`), commands name `world`.

    Each frame carries every body's pose for `worlds` and the `focus` world's joint state in
    its header, so one socket feeds both the 3D view and the panel.
    """
    loop, hub = _running(ws)
    if loop is None or hub is None:
        return await _refuse(ws, _CLOSE_TRY_AGAIN, "simulation is starting")
    nworld = loop.batch.nworld
    if focus is not None and not 0 <= focus < nworld:
        return await _refuse(ws, _CLOSE_POLICY, f"world {focus} does not exist (0..{nworld - 1})")
    try:
        if worlds is not None:
            ids = wire.parse_worlds(worlds, nworld)
        elif focus is not None:
            ids = np.array([focus])
        else:
            raise ValueError("worlds: give `worlds` or `focus`")
    except (ValueError, IndexError) as exc:
        return await _refuse(ws, _CLOSE_POLICY, str(exc))
    if len(ids) > MAX_VIEW_WORLDS:
        return await _refuse(
            ws, _CLOSE_POLICY, f"worlds: {len(ids)} asked, at most {MAX_VIEW_WORLDS} per view"
        )
    names = loop.spec.names

    def render(snap: Snapshot) -> bytes:
        st = loop.stats
        stats = {
            "mode": st.mode.value,
            "ticks_per_s": st.ticks_per_s,
            "realtime_factor": st.realtime_factor,
        }
        return wire.pose_frame(snap, ids, names, focus, stats)

    sub = Subscription(ids, rate, render, f"view:{focus}", binary=True)
    await _serve(ws, loop, hub, sub, default_world=None)


def _running(ws: WebSocket) -> tuple[SimLoop | None, StreamHub | None]:
    runtime = ws.app.state.runtime
    return runtime.loop, runtime.hub


async def _refuse(ws: WebSocket, code: int, reason: str) -> None:
    await ws.accept()
    await ws.close(code=code, reason=reason[:120])


async def _serve(
    ws: WebSocket, loop: SimLoop, hub: StreamHub, sub: Subscription, default_world: int | None
) -> None:
    await ws.accept()
    hub.add(sub)
    sub.offer(loop.latest, time.monotonic())  # the current state at once, then the stream
    writer = asyncio.create_task(_write(ws, hub, sub))
    try:
        while True:
            message = await ws.receive()
            if message["type"] == "websocket.disconnect":
                break
            while len(sub.acks) > _MAX_QUEUED_ACKS:
                await asyncio.sleep(0.005)
            text = message.get("text")
            if text is None:
                reply = {"op": "error", "id": None, "detail": "send JSON as text frames"}
            else:
                reply = _handle(loop, text, default_world)
            sub.push_ack(wire.dumps(reply))
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        hub.remove(sub)
        writer.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await writer


async def _write(ws: WebSocket, hub: StreamHub, sub: Subscription) -> None:
    while True:
        await sub.ready.wait()
        sub.ready.clear()
        while sub.acks:
            await ws.send_text(sub.acks.popleft().decode())
        snap, sub.latest = sub.latest, None
        if snap is None:
            continue
        frame = hub.frame(sub, snap)
        if sub.binary:
            await ws.send_bytes(frame)
        else:
            await ws.send_text(frame.decode())


def _handle(loop: SimLoop, text: str, default_world: int | None) -> dict[str, Any]:
    """One client message → ack or error (the socket stays open either way)."""
    msg_id: Any = None
    try:
        msg = orjson.loads(text)
        if not isinstance(msg, dict):
            raise CommandError("message", "a message must be a JSON object with an `op`")
        msg_id = msg.pop("id", None)
        op = msg.pop("op", None)
        world = msg.pop("world", default_world)
        if default_world is not None and world != default_world:
            raise CommandError("world", f"this socket controls world {default_world} only")
        if isinstance(world, bool) or not isinstance(world, int):
            raise CommandError("world", "`world` (an integer id) is required on this socket")
        if not 0 <= world < loop.batch.nworld:
            raise CommandError(
                "world", f"world {world} does not exist (0..{loop.batch.nworld - 1})"
            )
        handler = _OPS.get(op)
        if handler is None:
            raise CommandError("op", f"unknown op {op!r}; ops are {sorted(_OPS)}")
        return {"op": "ack", "id": msg_id, **handler(loop, world, msg)}
    except orjson.JSONDecodeError as exc:
        return {"op": "error", "id": msg_id, "detail": f"malformed JSON: {exc}"}
    except CommandError as exc:
        return {"op": "error", "id": msg_id, "detail": f"{exc.field}: {exc.message}"}
    except ValidationError as exc:
        return {"op": "error", "id": msg_id, "detail": _validation_detail(exc)}


def _validation_detail(exc: ValidationError) -> str:
    return "; ".join(
        f"{'.'.join(str(p) for p in err['loc']) or 'message'}: {err['msg']}" for err in exc.errors()
    )


def _increment(loop: SimLoop, world: int, msg: dict[str, Any]) -> dict[str, Any]:
    req = IncrementRequest.model_validate(msg)
    field = "deltas" if req.deltas is not None else "joint"
    r = loop.increment(world, resolve_joints(loop.spec, req.as_mapping(), field))
    return {"world": world, "tick": r.tick, "target": r.target, "clamped": r.clamped}


def _set_targets(loop: SimLoop, world: int, msg: dict[str, Any]) -> dict[str, Any]:
    req = JointTargets.model_validate(msg)
    values = resolve_joints(loop.spec, dict(zip(req.name, req.position, strict=True)), "name")
    r = loop.set_targets(world, values)
    return {"world": world, "tick": r.tick, "target": r.target, "clamped": r.clamped}


def _reset(loop: SimLoop, world: int, msg: dict[str, Any]) -> dict[str, Any]:
    if msg:
        raise CommandError(next(iter(msg)), "reset takes no fields besides op, id and world")
    tick = loop.reset([world])
    return {"world": world, "tick": tick, "target": loop.pending_targets(world), "clamped": []}


_OPS: dict[str, Callable[[SimLoop, int, dict[str, Any]], dict[str, Any]]] = {
    "increment": _increment,
    "set_targets": _set_targets,
    "reset": _reset,
}
