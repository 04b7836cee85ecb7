"""What the sync and async clients share: result types, request building, parsing, errors.

Nothing here does I/O. Each API call is described by a `Call` (method, path, body, and how to
parse the reply); `ArmfleetClient` runs it with `httpx.Client`, `AsyncArmfleetClient` with
`httpx.AsyncClient`. WebSocket messages are built and parsed here too, as is the reconnect
backoff, so the two twins differ only in how they wait.
"""

from __future__ import annotations

import itertools
import random
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlencode, urlsplit, urlunsplit

import numpy as np
import orjson
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus

DEFAULT_URL = "http://127.0.0.1:8000"
DEFAULT_TIMEOUT = 10.0
MODES = ("realtime", "fast", "paused")

# WebSocket close codes the service uses.
CLOSE_TRY_AGAIN = 1013  # still starting
CLOSE_POLICY = 1008  # unknown world / bad world list

JointRef = str | int
WorldSpec = int | str | Iterable[int] | None


# -- errors -------------------------------------------------------------------------------------


class ArmfleetError(Exception):
    """Any error from the service. `status` is the HTTP status (None: no HTTP reply at all) and
    `detail` the server's `detail` as it sent it (a string, or FastAPI's list of errors)."""

    def __init__(self, status: int | None, detail: Any, message: str | None = None) -> None:
        self.status = status
        self.detail = detail
        super().__init__(message or format_detail(detail))


class InvalidRequest(ArmfleetError):
    """422 (or 400): the request was refused as invalid; `detail` says which field and why."""


class NotFound(ArmfleetError):
    """404: no such world (or route)."""


class Conflict(ArmfleetError):
    """409: not possible in the current mode (e.g. step while not paused)."""


class PayloadTooLarge(ArmfleetError):
    """413: request body over the server's limit."""


class NotReady(ArmfleetError):
    """503: the service is up but the simulation is still starting (or failed to start)."""


class Unreachable(ArmfleetError):
    """No reply at all: connection refused, reset or timed out. `status` is None."""


class CommandRejected(ArmfleetError):
    """A WebSocket command answered with `{"op": "error"}`; `detail` is the server's text."""


_BY_STATUS: dict[int, type[ArmfleetError]] = {
    400: InvalidRequest,
    404: NotFound,
    409: Conflict,
    413: PayloadTooLarge,
    422: InvalidRequest,
    503: NotReady,
}


def format_detail(detail: Any) -> str:
    """FastAPI's `[{"loc": [...], "msg": ...}]` as `body.joint.bogus: unknown joint ...`."""
    if isinstance(detail, list):
        parts = []
        for err in detail:
            if isinstance(err, dict):
                loc = ".".join(str(p) for p in err.get("loc", []))
                parts.append(f"{loc}: {err.get('msg', '')}" if loc else str(err.get("msg", "")))
            else:
                parts.append(str(err))
        return "; ".join(parts)
    return str(detail)


def error_for(status: int, body: bytes) -> ArmfleetError:
    """The exception for a non-2xx reply, carrying the server's `detail`."""
    try:
        detail = orjson.loads(body).get("detail", body.decode(errors="replace"))
    except (orjson.JSONDecodeError, AttributeError):
        detail = body.decode(errors="replace") or f"HTTP {status}"
    cls = _BY_STATUS.get(status, ArmfleetError)
    return cls(status, detail, f"HTTP {status}: {format_detail(detail)}")


# -- results ------------------------------------------------------------------------------------


def _arr(values: Any, dtype: Any = np.float64) -> np.ndarray:
    # JSON null (a NaN on the server side) becomes NaN here.
    return np.array([np.nan if v is None else v for v in values], dtype=dtype)


def _arr2(rows: Any, width: int) -> np.ndarray:
    out = np.array([[np.nan if v is None else v for v in row] for row in rows], dtype=np.float64)
    return out.reshape(len(rows), width)


@dataclass(frozen=True)
class JointInfo:
    name: str
    lower: float
    upper: float
    home: float
    velocity_limit: float
    effort_limit: float


@dataclass(frozen=True)
class Info:
    """GET /v1/info: the robot, its joints, the batch and how fast time goes."""

    robot: str
    joints: tuple[JointInfo, ...]
    nworld: int
    device: str
    control_hz: float
    physics_dt: float
    substeps: int
    mode: str
    tick: int
    sim_time: float
    ticks_per_s: float
    realtime_factor: float
    captured: bool

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Info:
        fields = {k: d[k] for k in cls.__dataclass_fields__ if k != "joints"}
        return cls(joints=tuple(JointInfo(**j) for j in d["joints"]), **fields)


@dataclass(frozen=True, eq=False)
class WorldState:
    """One world at one tick: JointState fields (arrays of 7), target, flange pose, faults."""

    world: int
    tick: int
    sim_time: float
    name: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    target: np.ndarray
    flange_position: np.ndarray
    flange_quaternion: np.ndarray  # w x y z
    faults: int
    # Only while the service is paused: targets as of every accepted command (the next step's).
    pending_target: np.ndarray | None = None

    def index(self, joint: JointRef) -> int:
        return joint_index(self.name, joint)

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> WorldState:
        return cls(
            world=int(d["world"]),
            tick=int(d["tick"]),
            sim_time=float(d["sim_time"]),
            name=tuple(d["name"]),
            position=_arr(d["position"]),
            velocity=_arr(d["velocity"]),
            effort=_arr(d["effort"]),
            target=_arr(d["target"]),
            flange_position=_arr(d["flange"]["position"]),
            flange_quaternion=_arr(d["flange"]["quaternion"]),
            faults=int(d["faults"]),
            pending_target=_arr(d["pending_target"]) if "pending_target" in d else None,
        )


@dataclass(frozen=True, eq=False)
class BatchStates:
    """Several worlds at one tick; row i of every array belongs to `worlds[i]`."""

    tick: int
    name: tuple[str, ...]
    worlds: np.ndarray  # (n,) int
    sim_time: np.ndarray  # (n,)
    position: np.ndarray  # (n, 7)
    velocity: np.ndarray  # (n, 7)
    effort: np.ndarray  # (n, 7)
    target: np.ndarray  # (n, 7)
    flange_position: np.ndarray  # (n, 3)
    flange_quaternion: np.ndarray  # (n, 4) w x y z
    faults: np.ndarray  # (n,) int
    pending_target: np.ndarray | None = None  # (n, 7), only while the service is paused

    def __len__(self) -> int:
        return int(self.worlds.shape[0])

    def row(self, world: int) -> int:
        hits = np.flatnonzero(self.worlds == world)
        if hits.size == 0:
            raise KeyError(f"world {world} is not in this batch ({self.worlds.tolist()})")
        return int(hits[0])

    def world(self, world: int) -> WorldState:
        """One world of the batch as a WorldState."""
        i = self.row(world)
        return WorldState(
            world=int(world),
            tick=self.tick,
            sim_time=float(self.sim_time[i]),
            name=self.name,
            position=self.position[i],
            velocity=self.velocity[i],
            effort=self.effort[i],
            target=self.target[i],
            flange_position=self.flange_position[i],
            flange_quaternion=self.flange_quaternion[i],
            faults=int(self.faults[i]),
            pending_target=None if self.pending_target is None else self.pending_target[i],
        )

    def __iter__(self):
        return (self.world(int(w)) for w in self.worlds)

    @classmethod
    def from_rows(cls, d: Mapping[str, Any]) -> BatchStates:
        """GET /v1/worlds/state: `{"tick", "worlds": [<world state>, ...]}`."""
        rows = d["worlds"]
        names = tuple(rows[0]["name"]) if rows else ()
        return cls(
            tick=int(d["tick"]),
            name=names,
            worlds=np.array([r["world"] for r in rows], dtype=np.int64),
            sim_time=_arr([r["sim_time"] for r in rows]),
            position=_arr2([r["position"] for r in rows], len(names)),
            velocity=_arr2([r["velocity"] for r in rows], len(names)),
            effort=_arr2([r["effort"] for r in rows], len(names)),
            target=_arr2([r["target"] for r in rows], len(names)),
            flange_position=_arr2([r["flange"]["position"] for r in rows], 3),
            flange_quaternion=_arr2([r["flange"]["quaternion"] for r in rows], 4),
            faults=np.array([r["faults"] for r in rows], dtype=np.int64),
            pending_target=_arr2([r["pending_target"] for r in rows], len(names))
            if rows and "pending_target" in rows[0]
            else None,
        )

    @classmethod
    def from_columns(cls, d: Mapping[str, Any]) -> BatchStates:
        """A `{"op": "states"}` WebSocket frame (column-wise)."""
        names = tuple(d["name"])
        n = len(d["worlds"])
        return cls(
            tick=int(d["tick"]),
            name=names,
            worlds=np.array(d["worlds"], dtype=np.int64).reshape(n),
            sim_time=_arr(d["sim_time"]),
            position=_arr2(d["position"], len(names)),
            velocity=_arr2(d["velocity"], len(names)),
            effort=_arr2(d["effort"], len(names)),
            target=_arr2(d["target"], len(names)),
            flange_position=_arr2(d["flange_position"], 3),
            flange_quaternion=_arr2(d["flange_quaternion"], 4),
            faults=np.array(d["faults"], dtype=np.int64).reshape(n),
        )


@dataclass(frozen=True, eq=False)
class CommandAck:
    """Reply to a target command (HTTP or WebSocket): the world's 7 targets after it (clamped
    as the server clamps), the joints that hit a limit, and the first tick stepped with it."""

    world: int
    target: np.ndarray
    clamped: tuple[str, ...]
    tick: int
    id: Any = None  # the WebSocket message id it answers (None over HTTP)

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CommandAck:
        return cls(
            world=int(d["world"]),
            target=_arr(d["target"]),
            clamped=tuple(d.get("clamped", ())),
            tick=int(d["tick"]),
            id=d.get("id"),
        )


@dataclass(frozen=True, eq=False)
class BatchAck:
    """Reply to `set_many`: all results take effect at `tick`."""

    tick: int
    results: tuple[CommandAck, ...]

    @property
    def worlds(self) -> np.ndarray:
        return np.array([r.world for r in self.results], dtype=np.int64)

    @property
    def target(self) -> np.ndarray:
        return np.stack([r.target for r in self.results]) if self.results else np.zeros((0, 7))

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BatchAck:
        return cls(
            tick=int(d["tick"]), results=tuple(CommandAck.from_json(r) for r in d["results"])
        )


@dataclass(frozen=True)
class ResetResult:
    worlds: tuple[int, ...]
    tick: int

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ResetResult:
        return cls(worlds=tuple(d["worlds"]), tick=int(d["tick"]))


@dataclass(frozen=True)
class SimStatus:
    """Reply of pause / resume / set_mode / step: the mode now and the tick reached."""

    mode: str
    tick: int

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SimStatus:
        return cls(mode=str(d["mode"]), tick=int(d["tick"]))


@dataclass(frozen=True)
class ConnectionStatus:
    """Reported by `stream(..., on_status=...)` whenever the stream connects or drops.

    connected: a socket is open and frames flow
    detail: why it dropped (or the URL it connected to)
    attempt: consecutive failed attempts so far (0 when connected)
    retry_in: seconds until the next attempt (None when connected or giving up)
    """

    connected: bool
    detail: str
    attempt: int = 0
    retry_in: float | None = None


# -- joints and worlds --------------------------------------------------------------------------


def joint_index(names: Sequence[str], joint: JointRef) -> int:
    if isinstance(joint, int) and not isinstance(joint, bool):
        if 0 <= joint < len(names):
            return joint
        raise IndexError(f"joint index {joint} out of range 0..{len(names) - 1}")
    try:
        return list(names).index(joint)
    except ValueError:
        raise KeyError(f"unknown joint {joint!r}; joints are {list(names)}") from None


def _joint_key(joint: JointRef) -> str | int:
    if isinstance(joint, bool) or not isinstance(joint, str | int | np.integer):
        raise TypeError(f"a joint is a name or an index, not {joint!r}")
    return int(joint) if isinstance(joint, np.integer) else joint


def worlds_param(worlds: WorldSpec) -> str | None:
    """None → None (all); 3 → "3"; [0, 3, 7] → "0,3,7"; "0-63" stays as it is."""
    if worlds is None:
        return None
    if isinstance(worlds, str):
        return worlds
    if isinstance(worlds, int | np.integer):
        return str(int(worlds))
    return ",".join(str(int(w)) for w in worlds)


# -- HTTP calls ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Call:
    """One HTTP request and how to turn its JSON reply into a result."""

    method: str
    path: str
    parse: Callable[[Any], Any]
    json: Any = None
    params: Mapping[str, str] | None = None
    read_timeout: float | bool | None = False  # False: the client's timeout; None: no limit


def _identity(d: Any) -> Any:
    return d


def info_call() -> Call:
    return Call("GET", "/v1/info", Info.from_json)


def state_call(world: int) -> Call:
    return Call("GET", f"/v1/worlds/{int(world)}/state", WorldState.from_json)


def states_call(worlds: WorldSpec = None) -> Call:
    spec = worlds_param(worlds)
    return Call(
        "GET",
        "/v1/worlds/state",
        BatchStates.from_rows,
        params=None if spec is None else {"worlds": spec},
    )


def increment_body(joint: JointRef, delta: float) -> dict[str, Any]:
    return {"joint": _joint_key(joint), "delta": float(delta)}


def increment_call(world: int, joint: JointRef, delta: float) -> Call:
    path = f"/v1/worlds/{int(world)}/increments"
    return Call("POST", path, CommandAck.from_json, json=increment_body(joint, delta))


def targets_body(targets: Mapping[JointRef, float]) -> dict[str, Any]:
    """`{"elbow_joint": 1.2, 6: 0.7}` → JointState-shaped `{"name": [...], "position": [...]}`.

    Indices travel as digit strings; the server resolves either."""
    if not targets:
        raise ValueError("set_targets needs at least one joint")
    names = [str(_joint_key(j)) for j in targets]
    return {"name": names, "position": [float(v) for v in targets.values()]}


def set_targets_call(world: int, targets: Mapping[JointRef, float]) -> Call:
    path = f"/v1/worlds/{int(world)}/targets"
    return Call("PUT", path, CommandAck.from_json, json=targets_body(targets))


def set_many_call(worlds: Iterable[int], positions: Any) -> Call:
    ids = [int(w) for w in worlds]
    rows = np.asarray(positions, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[0] != len(ids):
        raise ValueError(f"positions must be ({len(ids)}, 7), got shape {rows.shape}")
    return Call(
        "POST", "/v1/targets", BatchAck.from_json, json={"worlds": ids, "position": rows.tolist()}
    )


def reset_call(world: int | Iterable[int] | None = None) -> Call:
    if world is None:
        return Call("POST", "/v1/reset", ResetResult.from_json)
    if isinstance(world, int | np.integer):
        return Call("POST", f"/v1/worlds/{int(world)}/reset", ResetResult.from_json)
    return Call(
        "POST", "/v1/reset", ResetResult.from_json, json={"worlds": [int(w) for w in world]}
    )


def pause_call() -> Call:
    return Call("POST", "/v1/sim/pause", SimStatus.from_json)


def resume_call() -> Call:
    return Call("POST", "/v1/sim/resume", SimStatus.from_json)


def set_mode_call(mode: str) -> Call:
    mode = str(getattr(mode, "value", mode))
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    return Call("POST", "/v1/sim/mode", SimStatus.from_json, json={"mode": mode})


def step_call(ticks: int = 1) -> Call:
    # The reply comes once the ticks are done: no read limit.
    return Call(
        "POST", "/v1/sim/step", SimStatus.from_json, json={"ticks": int(ticks)}, read_timeout=None
    )


def readyz_call() -> Call:
    return Call("GET", "/readyz", _identity)


def parse_reply(call: Call, status: int, body: bytes) -> Any:
    if status >= 400:
        raise error_for(status, body)
    return call.parse(orjson.loads(body))


# -- WebSocket ----------------------------------------------------------------------------------

BINARY_MAGIC = b"AFS1"  # batch frames sent with format=binary


def ws_url(
    base_url: str, worlds: WorldSpec, rate: float | None = None, binary: bool = False
) -> str:
    """http://host:port + 3 → ws://host:port/v1/ws/worlds/3; a list/range/None → /v1/ws?worlds=."""
    parts = urlsplit(base_url)
    scheme = {"http": "ws", "https": "wss"}.get(parts.scheme, parts.scheme)
    params: dict[str, str] = {}
    if rate is not None:
        params["rate"] = f"{float(rate):g}"
    if isinstance(worlds, int | np.integer):
        path = f"/v1/ws/worlds/{int(worlds)}"
    else:
        path = "/v1/ws"
        spec = worlds_param(worlds)
        if spec is not None:
            params = {"worlds": spec, **params}
        if binary:
            params["format"] = "binary"
    base_path = parts.path.rstrip("/")
    return urlunsplit((scheme, parts.netloc, base_path + path, urlencode(params), ""))


@dataclass(frozen=True)
class WsError:
    """`{"op": "error", "id", "detail"}` from the server."""

    id: Any
    detail: str


WsMessage = WorldState | BatchStates | CommandAck | WsError


def parse_binary_states(data: bytes) -> BatchStates:
    """A binary batch frame (`format=binary`; layout in service/wire.py) as BatchStates."""
    hlen = int.from_bytes(data[4:8], "little")
    header = orjson.loads(data[8 : 8 + hlen])
    n = header["n"]
    at = 8 + hlen
    worlds = np.frombuffer(data, "<i4", n, at).astype(np.int64)
    width = sum(w for _, w in header["columns"])
    rows = np.frombuffer(data, "<f4", n * width, at + 4 * n).reshape(n, width)
    cols: dict[str, np.ndarray] = {}
    col = 0
    for name, w in header["columns"]:
        cols[name] = rows[:, col : col + w] if w > 1 else rows[:, col]
        col += w
    return BatchStates(
        tick=int(header["tick"]),
        name=tuple(header["name"]),
        worlds=worlds,
        sim_time=cols["sim_time"].astype(np.float64),
        position=cols["position"],
        velocity=cols["velocity"],
        effort=cols["effort"],
        target=cols["target"],
        flange_position=cols["flange_position"],
        flange_quaternion=cols["flange_quaternion"],
        faults=cols["faults"].astype(np.int64),
    )


def parse_ws(text: str | bytes) -> WsMessage | None:
    """A server WebSocket message; None for an op this client does not know."""
    if isinstance(text, bytes) and text[:4] == BINARY_MAGIC:
        return parse_binary_states(text)
    d = orjson.loads(text)
    op = d.get("op")
    if op == "state":
        return WorldState.from_json(d)
    if op == "states":
        return BatchStates.from_columns(d)
    if op == "ack":
        return CommandAck.from_json(d)
    if op == "error":
        return WsError(id=d.get("id"), detail=str(d.get("detail")))
    return None


class CommandIds:
    """Message ids for commands over one socket, and the command messages themselves."""

    def __init__(self, world: int | None = None) -> None:
        self._counter = itertools.count(1)
        self.world = world  # sent as "world" (needed on the batch socket only)

    def _msg(self, op: str, fields: dict[str, Any], world: int | None) -> tuple[int, str]:
        msg_id = next(self._counter)
        msg: dict[str, Any] = {"op": op, "id": msg_id, **fields}
        w = self.world if world is None else world
        if w is not None:
            msg["world"] = int(w)
        return msg_id, orjson.dumps(msg).decode()

    def increment(self, joint: JointRef, delta: float, world: int | None = None):
        return self._msg("increment", increment_body(joint, delta), world)

    def set_targets(self, targets: Mapping[JointRef, float], world: int | None = None):
        return self._msg("set_targets", targets_body(targets), world)

    def reset(self, world: int | None = None):
        return self._msg("reset", {}, world)


def ack_or_raise(msg: CommandAck | WsError) -> CommandAck:
    if isinstance(msg, WsError):
        raise CommandRejected(None, msg.detail)
    return msg


WS_MAX_SIZE = 64 << 20  # a frame of thousands of worlds is several MiB
# What opening or reading a socket raises when the server is not (or no longer) there.
WS_DROPPED = (OSError, InvalidHandshake, TimeoutError)


def drop_reason(exc: BaseException) -> str:
    """A short, stable text for why a socket could not be opened or was lost."""
    if isinstance(exc, ConnectionRefusedError):
        return "connection refused"
    if isinstance(exc, TimeoutError):
        return "timed out"
    if isinstance(exc, InvalidStatus):
        return f"HTTP {exc.response.status_code} instead of a WebSocket"
    if isinstance(exc, ConnectionError):
        return "connection lost"
    return f"{type(exc).__name__}: {exc}"


def close_reason(code: int | None, reason: str | None) -> str:
    """Why the server closed a socket; raises NotFound where reconnecting cannot help."""
    reason = reason or ""
    if code == CLOSE_POLICY:
        raise NotFound(None, reason or "refused by the server (policy)")
    if code == CLOSE_TRY_AGAIN:
        return f"server is starting ({reason})"
    if code is None:
        return "connection lost"
    return f"closed by the server ({code} {reason})".strip()


def closed_exc_reason(exc: ConnectionClosed) -> str:
    rcvd = exc.rcvd
    return close_reason(rcvd.code, rcvd.reason) if rcvd is not None else "connection lost"


@dataclass
class Backoff:
    """Reconnect delays: `first`, doubling up to `maximum`, with ±20 % jitter."""

    first: float = 0.1
    maximum: float = 2.0
    attempt: int = field(default=0)

    def next(self) -> float:
        delay = min(self.maximum, self.first * (2**self.attempt))
        self.attempt += 1
        return delay * random.uniform(0.8, 1.2)

    def reset(self) -> None:
        self.attempt = 0


StatusCallback = Callable[[ConnectionStatus], None]


class Reconnector:
    """The reconnect policy of `stream()`, shared by the sync and async loops.

    `frame(text)` parses a message and returns the state to yield (None otherwise), reporting
    the connection as up on the first one; `dropped(reason)` reports the drop and returns the
    delay before the next attempt, or raises Unreachable when it is time to give up.
    """

    def __init__(
        self,
        url: str,
        reconnect: bool = True,
        on_status: StatusCallback | None = None,
        backoff: Backoff | None = None,
        give_up_after: float | None = None,
    ) -> None:
        self.url = url
        self.reconnect = reconnect
        self.on_status = on_status
        self.backoff = backoff or Backoff()
        self.give_up_after = give_up_after
        self.connected = False
        self._failing_since: float | None = None

    def opened(self) -> None:
        self.connected = False  # "up" once the first frame arrives

    def frame(self, text: str | bytes) -> WorldState | BatchStates | None:
        msg = parse_ws(text)
        if not isinstance(msg, WorldState | BatchStates):
            return None
        if not self.connected:
            self.connected = True
            self._failing_since = None
            self.backoff.reset()
            if self.on_status:
                self.on_status(ConnectionStatus(True, self.url))
        return msg

    def dropped(self, reason: str) -> float:
        self.connected = False
        now = time.monotonic()
        if self._failing_since is None:
            self._failing_since = now
        give_up = not self.reconnect or (
            self.give_up_after is not None and now - self._failing_since > self.give_up_after
        )
        if give_up:
            if self.on_status:
                self.on_status(ConnectionStatus(False, reason, self.backoff.attempt + 1))
            raise Unreachable(None, f"{self.url}: {reason}")
        delay = self.backoff.next()
        if self.on_status:
            self.on_status(ConnectionStatus(False, reason, self.backoff.attempt, delay))
        return delay
