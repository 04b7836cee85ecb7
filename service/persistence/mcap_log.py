"""The MCAP layout of an armfleet recording: what is written where, in schemas Foxglove reads.

- metadata `armfleet`: the batch header (`provenance.py`), recorded worlds and rate, the
  tick the recording starts at and the joint names; all values are strings (JSON for lists).
- attachment `state-<tick>.npz` (`snapshots.py` bytes): the full batch state the recording
  starts from and every state restored while recording; a replay starts from these.
- `/world_<w>/joint_states`: `sensor_msgs/msg/JointState` (ros2msg schema, CDR, as rosbag2
  writes it) of each recorded world: the seven commanded joints' position [rad], velocity
  [rad/s] and effort [N·m] as float64 (exactly the engine's numbers), header.stamp = the batch's
  simulated time tick × tick_dt; the message's publish_time is the same in ns, `sequence` the
  tick. Log time is the wall clock when the state was taken (so playback runs as it happened).
- `/armfleet/commands` (JSON schema): every accepted command: seq, source, kind (increment,
  set_targets, reset, mode), worlds, targets (the worlds' rows after it) [rad], tick (the first
  tick stepped with it), mode, joints (the joint indices a target command named; only those
  change in a replay, and only a trajectory driving one of them stops).
- `/armfleet/restores` (JSON schema): tick_before, tick (after), name, attachment.
- `/armfleet/status` (JSON schema): start, stop and the error that ended a recording early.
"""

from __future__ import annotations

import json
import struct
import time
from typing import IO, Any

import numpy as np
import orjson
from mcap.writer import Writer

from service.core.commands.registry import KINDS

JOINT_STATE = "sensor_msgs/msg/JointState"
# The interface definition as ROS 2 publishes it for this type (with its dependencies).
JOINT_STATE_MSGDEF = """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
COMMANDS = "/armfleet/commands"
RESTORES = "/armfleet/restores"
STATUS = "/armfleet/status"
METADATA = "armfleet"
# Metadata values are strings; these keys hold JSON (numbers, lists), the others plain text.
JSON_KEYS = frozenset(
    {
        "nworld",
        "control_hz",
        "physics_dt",
        "substeps",
        "versions",
        "worlds",
        "every_ticks",
        "rate",
        "start_tick",
        "joint_names",
    }
)


def parse_metadata(values: dict[str, str]) -> dict[str, Any]:
    """The inverse of `McapLog.metadata`."""
    return {k: json.loads(v) if k in JSON_KEYS else v for k, v in values.items()}


def joint_state_topic(world: int) -> str:
    return f"/world_{world}/joint_states"


def state_attachment(tick: int, seq: int) -> str:
    return f"state-{seq:04d}-tick{tick}.npz"


_COMMAND_SCHEMA = {
    "type": "object",
    "title": "armfleet command",
    "properties": {
        "seq": {"type": "integer", "description": "order of acceptance in this recording"},
        "source": {"type": "string", "description": "http, ws, browser, ros2, ... replay"},
        "kind": {
            "type": "string",
            "enum": list(KINDS),
        },
        "worlds": {"type": "array", "items": {"type": "integer"}},
        "targets": {
            "type": "array",
            "items": {"type": "array", "items": {"type": "number"}},
            "description": "each world's position targets after the command [rad]",
        },
        "tick": {"type": "integer", "description": "first tick stepped with the command"},
        "mode": {"type": ["string", "null"], "description": "new mode (kind mode)"},
        "joints": {
            "type": "array",
            "items": {"type": "integer"},
            "description": "joint indices a target command named (absent: all); only these "
            "change and only a trajectory driving one of them stops",
        },
        "trajectory": {
            "type": "object",
            "description": "kind trajectory: joint_names, points, tolerances (as POSTed)",
        },
    },
}
_RESTORE_SCHEMA = {
    "type": "object",
    "title": "armfleet restore",
    "properties": {
        "tick_before": {"type": "integer"},
        "tick": {"type": "integer"},
        "name": {"type": "string"},
        "attachment": {"type": "string", "description": "attachment holding the state"},
    },
}
_STATUS_SCHEMA = {
    "type": "object",
    "title": "armfleet recording status",
    "properties": {"event": {"type": "string"}, "tick": {"type": "integer"}, "detail": {}},
}


def _pad(buf: bytearray, align: int) -> None:
    """CDR aligns each primitive to its size, counted from the start of the body."""
    buf.extend(b"\0" * ((-(len(buf) - 4)) % align))


def _put_string(buf: bytearray, text: str) -> None:
    raw = text.encode() + b"\0"
    _pad(buf, 4)
    buf.extend(struct.pack("<I", len(raw)))
    buf.extend(raw)


class JointStateCdr:
    """Encodes sensor_msgs/JointState (little-endian CDR) for a fixed list of joint names.

    Everything after the stamp up to the arrays is the same for every message of a world, so it
    is built once; per message only the stamp and three float64 arrays are packed.
    """

    def __init__(self, names: list[str], frame_id: str = ""):
        self.njoint = len(names)
        head = bytearray(b"\x00\x01\x00\x00")  # CDR_LE encapsulation
        head.extend(b"\0" * 8)  # stamp, filled per message
        _put_string(head, frame_id)
        _pad(head, 4)
        head.extend(struct.pack("<I", len(names)))
        for n in names:
            _put_string(head, n)
        self._head = bytes(head)
        self._arrays_at = len(head)

    def encode(self, stamp_ns: int, position: Any, velocity: Any, effort: Any) -> bytes:
        buf = bytearray(self._head)
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        struct.pack_into("<iI", buf, 4, sec, nanosec)
        for values in (position, velocity, effort):
            arr = np.asarray(values, dtype="<f8")
            _pad(buf, 4)
            buf.extend(struct.pack("<I", arr.size))
            if arr.size:
                _pad(buf, 8)
                buf.extend(arr.tobytes())
        return bytes(buf)


def decode_joint_state(data: bytes) -> tuple[int, list[str], np.ndarray, np.ndarray, np.ndarray]:
    """(stamp ns, names, position, velocity, effort) from CDR bytes (replay's reader)."""
    off = 4

    def align(k: int) -> None:
        nonlocal off
        off += (-(off - 4)) % k

    def u32() -> int:
        nonlocal off
        align(4)
        (v,) = struct.unpack_from("<I", data, off)
        off += 4
        return v

    def string() -> str:
        nonlocal off
        n = u32()
        s = data[off : off + n - 1].decode()
        off += n
        return s

    sec, nanosec = struct.unpack_from("<iI", data, off)
    off += 8
    string()  # frame_id
    names = [string() for _ in range(u32())]
    arrays = []
    for _ in range(3):
        n = u32()
        if n:
            align(8)
        arrays.append(np.frombuffer(data, dtype="<f8", count=n, offset=off).astype(np.float64))
        off += 8 * n
    return sec * 1_000_000_000 + nanosec, names, arrays[0], arrays[1], arrays[2]


class _Counted:
    """A write-only stream that knows its position without seeking, so that a recording can go
    to a pipe or FIFO as well as to a file (the MCAP writer asks `tell()` for its indexes)."""

    def __init__(self, stream: IO[bytes]):
        self._stream = stream
        self._pos = 0

    def write(self, data: bytes) -> int:
        self._stream.write(data)
        self._pos += len(data)
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        self._stream.flush()


class McapLog:
    """Writes one recording. Not thread-safe: the recorder's writer thread owns it."""

    def __init__(self, stream: IO[bytes], header: dict[str, Any], names: list[str]):
        self._writer = Writer(_Counted(stream), chunk_size=256 * 1024)
        self._writer.start(profile="ros2", library="armfleet")
        self._names = names
        self._hz = float(header["control_hz"])
        self._cdr = JointStateCdr(names)
        js = self._writer.register_schema(
            name=JOINT_STATE, encoding="ros2msg", data=JOINT_STATE_MSGDEF.encode()
        )
        self._js_schema = js
        self._world_channel: dict[int, int] = {}
        self._json_channel = {
            topic: self._writer.register_channel(
                topic=topic,
                message_encoding="json",
                schema_id=self._writer.register_schema(
                    name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
                ),
            )
            for topic, schema in (
                (COMMANDS, _COMMAND_SCHEMA),
                (RESTORES, _RESTORE_SCHEMA),
                (STATUS, _STATUS_SCHEMA),
            )
        }
        self._seq = 0
        self._attachments = 0

    def stamp_ns(self, tick: int) -> int:
        """Simulated time of a tick in ns (tick × tick_dt, rounded; `tick_of` inverts it)."""
        return round(tick * 1e9 / self._hz)

    def metadata(self, values: dict[str, Any]) -> None:
        self._writer.add_metadata(
            METADATA,
            {k: json.dumps(v) if k in JSON_KEYS else str(v) for k, v in values.items()},
        )

    def attach_state(self, tick: int, data: bytes, wall_ns: int | None = None) -> str:
        name = state_attachment(tick, self._attachments)
        self._attachments += 1
        now = wall_ns or time.time_ns()
        self._writer.add_attachment(now, now, name, "application/x-npz", data)
        return name

    def joint_states(self, wall_ns: int, tick: int, worlds: np.ndarray, snapshot: Any) -> None:
        """One JointState per recorded world from a `Snapshot` taken at `tick`."""
        stamp = self.stamp_ns(tick)
        for w in worlds:
            w = int(w)
            channel = self._world_channel.get(w)
            if channel is None:
                channel = self._writer.register_channel(
                    topic=joint_state_topic(w), message_encoding="cdr", schema_id=self._js_schema
                )
                self._world_channel[w] = channel
            data = self._cdr.encode(
                stamp, snapshot.position[w], snapshot.velocity[w], snapshot.effort[w]
            )
            self._writer.add_message(
                channel, log_time=wall_ns, data=data, publish_time=stamp, sequence=tick & 0xFFFFFFFF
            )

    def json(self, topic: str, wall_ns: int, body: dict[str, Any]) -> None:
        if topic == COMMANDS:
            body = {"seq": self._seq, **body}
            self._seq += 1
        data = orjson.dumps(body, option=orjson.OPT_SERIALIZE_NUMPY)
        self._writer.add_message(
            self._json_channel[topic], log_time=wall_ns, data=data, publish_time=wall_ns
        )

    def finish(self) -> None:
        self._writer.finish()


def tick_of(stamp_ns: int, control_hz: float) -> int:
    """The tick whose simulated time is `stamp_ns` (inverse of `McapLog.stamp_ns`)."""
    return round(stamp_ns * control_hz / 1e9)
