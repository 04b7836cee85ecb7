"""The WebSocket half of the client without I/O: URLs, frames, commands, drops and reconnects.

The sync (`websockets.sync`) and async (`websockets.asyncio`) twins only open sockets, read and
wait; which URL to open, what a frame means, why a socket closed and how long to wait before
trying again are decided here, once.
"""

from __future__ import annotations

import contextlib
import itertools
import random
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, TypedDict
from urllib.parse import urlencode, urlsplit, urlunsplit

import numpy as np
import orjson
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus, InvalidURI

from clients.calls import (
    DEFAULT_TIMEOUT,
    auth_headers,
    increment_body,
    targets_body,
    worlds_param,
)
from clients.entity_states import EntityStates
from clients.errors import ArmfleetError, CommandRejected, NotFound, Unreachable, unreachable
from clients.models import (
    BatchStates,
    CommandAck,
    ConnectionStatus,
    JointRef,
    WorldSpec,
    WorldState,
    WsError,
)
from clients.wire import BINARY_MAGIC, safety_modes

# WebSocket close codes the service uses.
CLOSE_TRY_AGAIN = 1013  # still starting
CLOSE_POLICY = 1008  # unknown world / bad world list

MAX_SIZE = 64 << 20  # a frame of thousands of worlds is several MiB
# What opening or reading a socket raises when the server is not (or no longer) there.
DROPPED = (OSError, InvalidHandshake, TimeoutError)

WsMessage = WorldState | BatchStates | CommandAck | WsError
StatusCallback = Callable[[ConnectionStatus], None]


def ws_url(
    base_url: str,
    worlds: WorldSpec,
    rate: float | None = None,
    binary: bool = False,
    entities: bool = False,
) -> str:
    """http://host:port + 3 → ws://host:port/v1/ws/worlds/3; a list/range/None → /v1/ws?worlds=.

    `entities`: frames carry the entities too (`.entities` of the states parsed)."""
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
    if entities:
        params["entities"] = "true"
    base_path = parts.path.rstrip("/")
    return urlunsplit((scheme, parts.netloc, base_path + path, urlencode(params), ""))


# -- frames -------------------------------------------------------------------------------------


def parse_binary_states(data: bytes) -> BatchStates:
    """A binary batch frame (`format=binary`; layout in clients/wire.py) as
    BatchStates."""
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
    at += 4 * n * (1 + width)
    if "entities" in header:  # asked with entities=True: float32[n, ne, 13] after the rows
        cols["entities"] = entities = EntityStates.from_block(header["entities"], data, at, n)
        at += 4 * n * len(entities.name) * sum(w for _, w in header["entities"]["columns"])
    return BatchStates(
        tick=int(header["tick"]),
        name=tuple(header["name"]),
        worlds=worlds,
        sim_time=cols.pop("sim_time").astype(np.float64),
        faults=cols.pop("faults").astype(np.int64),
        safety_mode=safety_modes(header, data, at, n),  # None from a layout-1 server
        **cols,
    )


def parse(text: str | bytes) -> WsMessage | None:
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


def ack_or_raise(msg: CommandAck | WsError) -> CommandAck:
    """The ack, or CommandRejected carrying the server's reason."""
    if isinstance(msg, WsError):
        raise CommandRejected(None, msg.detail)
    return msg


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

    def op(self, op: str, body: dict[str, Any], world: int | None = None):
        """Any other op with its body (clients.cartesian's jog and tcp_target)."""
        return self._msg(op, body, world)


class WorldLink:
    """What a session with one world's socket holds, blocking or asyncio: the socket's URL,
    the world, how long a command waits for its ack, the token of the handshake, the ids its
    commands go out with and the newest state it has read."""

    def __init__(
        self, url: str, world: int, timeout: float = DEFAULT_TIMEOUT, token: str | None = None
    ) -> None:
        self.url = url
        self.world = world
        self.timeout = timeout
        self.token = token
        self.latest: WorldState | None = None
        self._ids = CommandIds()


# -- drops --------------------------------------------------------------------------------------


def connect_options(timeout: float, token: str | None) -> dict[str, Any]:
    """What both clients open a WebSocket with (websockets' `connect`, sync or asyncio): the
    handshake's timeout, frames of up to MAX_SIZE, no proxy, the token's header."""
    return {
        "open_timeout": timeout,
        "max_size": MAX_SIZE,
        "proxy": None,
        "additional_headers": auth_headers(token),
    }


@contextlib.contextmanager
def bad_url() -> Iterator[None]:
    """A URL websockets cannot open is the caller's mistake (ArmfleetError), not a drop."""
    try:
        yield
    except InvalidURI as exc:
        raise ArmfleetError(None, str(exc)) from exc


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
    """`close_reason` for the exception a read or send raised."""
    rcvd = exc.rcvd
    return close_reason(rcvd.code, rcvd.reason) if rcvd is not None else "connection lost"


LOST = (ConnectionClosed, *DROPPED)  # everything `reason_for` explains


def reason_for(exc: BaseException) -> str:
    """Why a socket was closed (`ConnectionClosed`) or could not be opened or kept (`DROPPED`);
    NotFound where the server refused it for good."""
    if isinstance(exc, ConnectionClosed):
        return closed_exc_reason(exc)
    return drop_reason(exc)


def lost(url: str, exc: BaseException) -> Unreachable:
    """Unreachable for a socket that could not be opened or was closed under a command."""
    return unreachable(url, reason_for(exc))


# -- reconnect policy ---------------------------------------------------------------------------


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


class StreamOptions(TypedDict, total=False):
    """The keyword options of `stream()` (sync and async alike); see `Reconnector`."""

    reconnect: bool  # False: raise Unreachable on the first drop (default True)
    on_status: StatusCallback | None  # hears every connect and drop
    backoff: Backoff | None  # reconnect delays (default Backoff())
    give_up_after: float | None  # seconds of failing in a row before Unreachable
    binary: bool  # batch streams as float32 frames
    entities: bool  # frames carry each entity's pose and twist


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

    @classmethod
    def for_stream(
        cls, base_url: str, worlds: WorldSpec, rate: float | None, options: StreamOptions
    ) -> Reconnector:
        """The policy (and, as `.url`, the socket URL) of one `stream()` call."""
        opts = dict(options)
        binary, entities = bool(opts.pop("binary", False)), bool(opts.pop("entities", False))
        url = ws_url(base_url, worlds, rate, binary, entities)
        return cls(url, **opts)

    def opened(self) -> None:
        self.connected = False  # "up" once the first frame arrives

    def frame(self, text: str | bytes) -> WorldState | BatchStates | None:
        msg = parse(text)
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
            raise unreachable(self.url, reason)
        delay = self.backoff.next()
        if self.on_status:
            self.on_status(ConnectionStatus(False, reason, self.backoff.attempt, delay))
        return delay
