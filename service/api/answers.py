"""How the per-world routes read and answer, in one place: read-your-writes state reads and
JSON replies serialised directly.

Why a module of its own: the world, Cartesian and trajectory routes all answer the same way
(orjson straight into the reply, skipping FastAPI's re-validation through the response
model: the hot path of the Up/Down buttons) and read a world's state the same way (waiting
for the tick its accepted commands take effect at). Each route module had its own copy of
the reply helper, and the Cartesian routes imported the world routes' private ones.
"""

from __future__ import annotations

import asyncio
import dataclasses
from typing import Any

import numpy as np
from fastapi.responses import Response

from service.core.errors import Unavailable
from service.core.sim.loop import SimLoop
from service.core.sim.loop_types import CommandResult
from service.core.sim.types import Mode, Snapshot
from service.core.streams import entity_frames, wire

# A read waits at most this long for the tick its worlds' commands take effect at (normally
# one or two ticks); longer means the engine is not advancing (see /readyz).
READ_TIMEOUT = 5.0


def json_reply(payload: Any) -> Response:
    """`payload` as a JSON reply, serialised directly with orjson (numpy arrays included)."""
    return Response(wire.dumps(payload), media_type="application/json")


def command_ack(result: CommandResult) -> Response:
    """The reply of an accepted per-world target command (CommandReply): its world, targets,
    what was clamped and the tick it takes effect at."""
    return json_reply(wire.command_reply(result))


async def read_fresh(
    loop: SimLoop, worlds: np.ndarray | list[int], with_entities: bool = False
) -> tuple[Snapshot, np.ndarray | None]:
    """Read-your-writes: a snapshot including every accepted command for `worlds` and the
    worlds' safety modes as of now, and while paused their pending targets (which the next
    step puts in effect). `with_entities`: then one taken on the sim thread with the entities
    of its own tick (entity_frames.py)."""
    try:
        snap = await asyncio.wait_for(
            asyncio.wrap_future(loop.fresh_snapshot(worlds)), timeout=READ_TIMEOUT
        )
        if with_entities:
            fut = loop.call(lambda b: entity_frames.attach(b.snapshot(), b))
            snap = await asyncio.wait_for(asyncio.wrap_future(fut), timeout=READ_TIMEOUT)
    except TimeoutError:
        why = loop.failure or "no tick completed"
        raise Unavailable(f"the engine is not advancing ({why}); see /readyz") from None
    pending = (
        loop.commands.pending_targets(np.asarray(worlds)) if loop.mode is Mode.PAUSED else None
    )
    # the safety mode as of now: a stop, an unlock or a reset between two ticks (paused: no
    # tick comes) is read at once, like the pending targets
    return dataclasses.replace(snap, safety=loop.safety.modes()), pending
