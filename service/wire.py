"""Snapshot → JSON bytes, shared by HTTP replies and WebSocket frames.

orjson serialises numpy arrays directly (float32 in its shortest form, NaN as null), which keeps
per-frame cost low when hundreds of worlds are streamed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import orjson

from service.errors import ArmfleetError, BadCommand, UnknownWorld
from service.types import Snapshot

if TYPE_CHECKING:
    from service.loop import CommandResult

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


def world_state(snap: Snapshot, world: int, names: list[str]) -> dict[str, Any]:
    """One world as sensor_msgs/JointState fields plus target, flange and fault count."""
    return {
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
    }


def states(snap: Snapshot, worlds: np.ndarray, names: list[str]) -> dict[str, Any]:
    return {"tick": snap.tick, "worlds": [world_state(snap, int(w), names) for w in worlds]}


def single_frame(snap: Snapshot, world: int, names: list[str]) -> bytes:
    return dumps({"op": "state", **world_state(snap, world, names)})


def batch_frame(snap: Snapshot, worlds: np.ndarray, names: list[str]) -> bytes:
    """Many worlds in one frame, column-wise (row i of each array belongs to worlds[i])."""
    return dumps(
        {
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
        }
    )


# Binary batch frames: b"AFS1", uint32 header length, JSON header, int32 world ids, then one
# float32 row per world holding these columns side by side (all little-endian).
BINARY_MAGIC = b"AFS1"
BINARY_COLUMNS = (
    ("sim_time", 1),
    ("position", 7),
    ("velocity", 7),
    ("effort", 7),
    ("target", 7),
    ("flange_position", 3),
    ("flange_quaternion", 4),
    ("faults", 1),
)


def batch_frame_binary(snap: Snapshot, worlds: np.ndarray, names: list[str]) -> bytes:
    """The batch frame as float32 rows: ~4x smaller than JSON and no per-number formatting."""
    header = dumps(
        {
            "op": "states",
            "tick": snap.tick,
            "n": len(worlds),
            "name": names,
            "columns": BINARY_COLUMNS,
        }
    )
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
        )
    )


# Pose frames (the browser page's stream, WS /v1/ws/view): every body's world pose for the viewed
# worlds, plus, in the header, the focused world's joint state and the loop's speed.
#   b"AFP1"
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
POSE_MAGIC = b"AFP1"


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


def parse_worlds(spec: str, nworld: int) -> np.ndarray:
    """'0-63,70,72-75' (the `worlds` query of HTTP and WebSocket) → sorted unique world ids.

    BadCommand for text that is not a list of ids/ranges, UnknownWorld for ids that do not exist.
    """
    out: set[int] = set()
    for part in spec.split(","):
        part = part.strip()
        if not part:
            continue
        lo_s, sep, hi_s = part.partition("-")
        try:
            lo = int(lo_s)
            hi = int(hi_s) if sep else lo
        except ValueError:
            raise BadCommand(_WORLDS, f"{part!r} is not an id or a range like 0-63") from None
        if lo > hi:
            raise BadCommand(_WORLDS, f"range {part!r} is empty")
        if lo < 0 or hi >= nworld:
            raise UnknownWorld(part, nworld)
        out.update(range(lo, hi + 1))
    if not out:
        raise BadCommand(_WORLDS, "no world ids given")
    return np.array(sorted(out), dtype=np.int64)


_WORLDS = "query.worlds"


def pick_worlds(spec: str | None, nworld: int, default_count: int = 8) -> list[int]:
    """Worlds an add-on (recorder, Foxglove) covers: `spec` parsed strictly, or by default the
    first `default_count` (all of a smaller batch)."""
    if spec is None:
        return list(range(min(default_count, nworld)))
    return [int(w) for w in parse_worlds(spec, nworld)]
