"""Snapshot → JSON bytes, shared by HTTP replies and WebSocket frames.

orjson serialises numpy arrays directly (float32 in its shortest form, NaN as null), which keeps
per-frame cost low when hundreds of worlds are streamed.
"""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson

from clients.wire import BINARY_COLUMNS, BINARY_LAYOUT, BINARY_MAGIC, ENTITY_COLUMNS, POSE_MAGIC
from service.core.errors import ArmfleetError
from service.core.sim import safety
from service.core.sim.types import EntityFrame, Snapshot

if TYPE_CHECKING:
    from service.core.sim.loop_types import CommandResult

_OPTS = orjson.OPT_SERIALIZE_NUMPY


def dumps(obj: Any) -> bytes:
    return orjson.dumps(obj, option=_OPTS)


def command_reply(result: CommandResult) -> dict[str, Any]:
    """The one reply shape of a target command, over HTTP and in WebSocket acks alike."""
    return {
        "world": result.world,
        "target": result.target,
        "clamped": result.clamped,
        "tick": result.tick,
    }


def ack(msg_id: Any, result: CommandResult) -> dict[str, Any]:
    """A WebSocket ack: the command reply plus the client's `id`."""
    return {"op": "ack", "id": msg_id, **command_reply(result)}


def error_frame(msg_id: Any, error: ArmfleetError | str) -> dict[str, Any]:
    """A WebSocket error frame: `detail` is "field: message" as in the HTTP 4xx bodies."""
    return {"op": "error", "id": msg_id, "detail": str(error)}


def world_state(
    snap: Snapshot,
    world: int,
    names: list[str],
    pending: np.ndarray | None = None,
    entities: bool = False,
) -> dict[str, Any]:
    """One world as sensor_msgs/JointState fields plus target, flange, fault count and safety
    mode ("NORMAL" or "PROTECTIVE_STOP": core/sim/safety.py).

    `pending` (paused only): the world's targets as of every accepted command. `entities`: the
    world's entities too (`entity_list`; the snapshot must carry them).
    """
    out = {
        "world": world,
        "tick": snap.tick,
        "sim_time": float(snap.sim_time[world]),
        "name": names,
        "position": snap.position[world],
        "velocity": snap.velocity[world],
        "effort": snap.effort[world],
        "target": snap.target[world],
        "flange": {"position": snap.flange_pos[world], "quaternion": snap.flange_quat[world]},
        "faults": int(snap.faults[world]),
        "safety_mode": _safety_names(snap, np.array([world]))[0],
    }
    if pending is not None:
        out["pending_target"] = pending
    if entities:
        out["entities"] = entity_list(_entities_of(snap), world)
    return out


def _safety_names(snap: Snapshot, worlds: np.ndarray) -> list[str]:
    """The worlds' safety modes by name (an engine's own snapshot has none: all NORMAL)."""
    if snap.safety is None:
        return ["NORMAL"] * len(worlds)
    return safety.names(snap.safety[worlds])


def safety_block(modes: np.ndarray | None, n: int) -> bytes:
    """A binary frame's last block: uint8[n], each world's safety mode as UR numbers it
    (`modes`, those of the frame's worlds; None: all NORMAL, as for an engine's snapshot)."""
    if modes is None:
        return bytes((safety.NORMAL,)) * n
    return np.asarray(modes, dtype=np.uint8).tobytes()


def _entities_of(snap: Snapshot) -> EntityFrame:
    if snap.entities is None:  # a caller's bug: entities are read with the snapshot
        raise ValueError(f"the snapshot of tick {snap.tick} was taken without entities")
    return snap.entities


def entity_list(frame: EntityFrame, world: int) -> list[dict[str, Any]]:
    """One world's entities as GET /v1/worlds/{w}/entities lists them (name, position,
    orientation w x y z, linear, angular)."""
    row = int(np.searchsorted(frame.worlds, world))
    return [
        {
            "name": name,
            "position": frame.position[row, e],
            "orientation": frame.orientation[row, e],
            "linear": frame.linear[row, e],
            "angular": frame.angular[row, e],
        }
        for e, name in enumerate(frame.names)
    ]


def entity_columns(frame: EntityFrame) -> dict[str, Any]:
    """A batch frame's `entities`, column-wise like the rest of it: `name` (ne,), then
    `position` (n, ne, 3), `orientation` (n, ne, 4, w x y z), `linear` and `angular`
    (n, ne, 3); row i belongs to the frame's worlds[i]."""
    if not frame.names:  # orjson writes no array with a zero-length axis
        empty = [[] for _ in frame.worlds]
        return {
            "name": [],
            "position": empty,
            "orientation": empty,
            "linear": empty,
            "angular": empty,
        }
    return {
        "name": list(frame.names),
        "position": frame.position,
        "orientation": frame.orientation,
        "linear": frame.linear,
        "angular": frame.angular,
    }


def states(
    snap: Snapshot,
    worlds: np.ndarray,
    names: list[str],
    pending: np.ndarray | None = None,
    entities: bool = False,
) -> dict[str, Any]:
    """Several worlds; `pending` (paused only) holds one row of pending targets per world;
    `entities`: each world's entities too."""
    rows = [
        world_state(snap, int(w), names, None if pending is None else pending[i], entities)
        for i, w in enumerate(worlds)
    ]
    return {"tick": snap.tick, "worlds": rows}


def single_frame(
    snap: Snapshot,
    world: int,
    names: list[str],
    trajectory: dict[str, Any] | None = None,
    entities: bool = False,
) -> bytes:
    """One world's state frame; `trajectory`: its trajectory's id, state, reason, progress;
    `entities`: the world's entities (`entity_list`) after `faults`."""
    state = world_state(snap, world, names, None, entities)
    return dumps({"op": "state", **state, "trajectory": trajectory})


def batch_frame(
    snap: Snapshot,
    worlds: np.ndarray,
    names: list[str],
    trajectories: dict[str, Any] | None = None,
    entities: bool = False,
) -> bytes:
    """Many worlds in one frame, column-wise (row i of each array belongs to worlds[i]);
    `trajectories`: world id → its trajectory's id, state, reason, progress (those that ran one);
    `entities`: the worlds' entities (`entity_columns`), last.
    """
    frame: dict[str, Any] = {
        "op": "states",
        "tick": snap.tick,
        "name": names,
        "worlds": worlds,
        "sim_time": snap.sim_time[worlds],
        "position": snap.position[worlds],
        "velocity": snap.velocity[worlds],
        "effort": snap.effort[worlds],
        "target": snap.target[worlds],
        "flange_position": snap.flange_pos[worlds],
        "flange_quaternion": snap.flange_quat[worlds],
        "faults": snap.faults[worlds],
        "safety_mode": _safety_names(snap, worlds),
        "trajectories": trajectories or {},
    }
    if entities:
        frame["entities"] = entity_columns(_entities_of(snap).take(worlds))
    return dumps(frame)


# Binary batch frames: layout, magic and columns in clients/wire.py (the readers' side too).


def binary_header(
    tick: int, n: int, names: list[str], entities: EntityFrame | None = None
) -> dict[str, Any]:
    """A binary batch frame's JSON header (with the entity block's, when it has one)."""
    out: dict[str, Any] = {
        "op": "states",
        "tick": tick,
        "n": n,
        "name": names,
        "columns": BINARY_COLUMNS,
        "layout": BINARY_LAYOUT,
    }
    if entities is not None:
        out["entities"] = {"name": list(entities.names), "columns": ENTITY_COLUMNS}
    return out


def entity_block(frame: EntityFrame) -> bytes:
    """The binary frame's entity block: float32[n, ne, 13] (layout above)."""
    return np.concatenate(frame.arrays(), axis=2, dtype="<f4").tobytes()


def batch_frame_binary(
    snap: Snapshot, worlds: np.ndarray, names: list[str], entities: bool = False
) -> bytes:
    """The batch frame as float32 rows: ~4x smaller than JSON and no per-number formatting;
    `entities`: the worlds' entities follow the rows; the safety block ends it (layout in
    clients/wire.py)."""
    frame = _entities_of(snap).take(worlds) if entities else None
    header = dumps(binary_header(snap.tick, len(worlds), names, frame))
    rows = np.concatenate(
        [
            snap.sim_time[worlds, None],
            snap.position[worlds],
            snap.velocity[worlds],
            snap.effort[worlds],
            snap.target[worlds],
            snap.flange_pos[worlds],
            snap.flange_quat[worlds],
            snap.faults[worlds, None],
        ],
        axis=1,
        dtype="<f4",
    )
    return b"".join(
        (
            BINARY_MAGIC,
            len(header).to_bytes(4, "little"),
            header,
            worlds.astype("<i4").tobytes(),
            rows.tobytes(),
            b"" if frame is None else entity_block(frame),
            safety_block(None if snap.safety is None else snap.safety[worlds], len(worlds)),
        )
    )


# Pose frames (the browser page's stream, WS /v1/ws/view): every body's world pose for the viewed
# worlds, plus, in the header, the focused world's joint state and the loop's speed.
#   POSE_MAGIC (clients/wire.py)
#   uint32 H: header length, a multiple of 4 (the JSON is padded with spaces) so that what
#             follows is 4-byte aligned and can be viewed in place (Float32Array in a browser)
#   H bytes of JSON: {"op": "poses", "tick", "n" (worlds), "nbody", "stats": {"mode",
#             "ticks_per_s", "realtime_factor"} | null, "focus": <world state as in
#             GET /v1/worlds/{w}/state> | null}
#   int32[n]  world ids
#   int32[n]  faults per world (times reset for NaN or capacity overflow)
#   float32[n, nbody, 7]  per world, per body (MjModel order, 0 = world; see GET /v1/scene):
#             x y z [m], then the orientation quaternion w x y z, world frame
# All little-endian. 64 worlds of our 19-body scene: ~34 KB per frame. While nothing shown
# changes (poses within 1e-4, targets, faults) the socket sends one frame every 0.5 s only.


def pose_frame(
    snap: Snapshot,
    worlds: np.ndarray,
    names: list[str],
    focus: int | None = None,
    stats: dict[str, Any] | None = None,
) -> bytes:
    """The pose frame for `worlds` (layout above); `focus` adds that world's joint state."""
    header = dumps(
        {
            "op": "poses",
            "tick": snap.tick,
            "n": len(worlds),
            "nbody": int(snap.body_pos.shape[1]),
            "stats": stats,
            "focus": None if focus is None else world_state(snap, focus, names),
        }
    )
    header += b" " * (-len(header) % 4)
    poses = np.concatenate((snap.body_pos[worlds], snap.body_quat[worlds]), axis=2, dtype="<f4")
    return b"".join(
        (
            POSE_MAGIC,
            len(header).to_bytes(4, "little"),
            header,
            worlds.astype("<i4").tobytes(),
            snap.faults[worlds].astype("<i4").tobytes(),
            poses.tobytes(),
        )
    )


# -- reading client messages leniently (to answer them properly) ------------------------------

_ID_RE = re.compile(r'"id"\s*:\s*("(?:[^"\\]|\\.)*"|-?[0-9]+(?:\.[0-9]+)?)')


def loads_lenient(text: str) -> Any:
    """JSON that may hold NaN/Infinity (Python's json reads them; orjson refuses), else None.

    The control layer then refuses the non-finite value by name, with the message's id.
    """
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        return None


def read_id(text: str) -> Any:
    """The `id` of a message, whatever else is wrong with it (None when none can be read)."""
    try:
        msg = orjson.loads(text)
    except orjson.JSONDecodeError:
        msg = loads_lenient(text)
    if isinstance(msg, dict):
        return msg.get("id")
    if msg is not None:
        return None
    found = _ID_RE.search(text)
    if found is None:
        return None
    try:
        return json.loads(found.group(1))
    except ValueError:
        return None
