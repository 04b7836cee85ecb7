"""Blocking client: `ArmfleetClient` (httpx) and `WorldSession` (websockets.sync).

    with ArmfleetClient("http://127.0.0.1:8000") as arm:
        arm.wait_ready(60)
        arm.increment(0, "elbow_joint", 0.1)
        for state in arm.stream(0, rate=10):
            print(state.tick, state.position)

The asynchronous twin, with the same methods, is `clients.async_client.AsyncArmfleetClient`.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

import httpx
from websockets.exceptions import ConnectionClosed, InvalidURI
from websockets.sync.client import ClientConnection
from websockets.sync.client import connect as ws_connect

from clients import _core
from clients._core import (
    DEFAULT_TIMEOUT,
    DEFAULT_URL,
    ArmfleetError,
    BatchAck,
    BatchStates,
    Call,
    CommandAck,
    Info,
    JointRef,
    NotReady,
    ResetResult,
    SimStatus,
    Unreachable,
    WorldSpec,
    WorldState,
)


class ArmfleetClient:
    """REST + WebSocket client for one armfleet service. Thread-safe for HTTP calls."""

    def __init__(self, url: str = DEFAULT_URL, timeout: float = DEFAULT_TIMEOUT) -> None:
        self.url = url.rstrip("/")
        self.timeout = timeout
        self._http = httpx.Client(base_url=self.url, timeout=timeout)

    # -- plumbing ----------------------------------------------------------------------------

    def _call(self, call: Call) -> Any:
        kwargs: dict[str, Any] = {"params": call.params, "json": call.json}
        if call.read_timeout is not False:
            kwargs["timeout"] = httpx.Timeout(self.timeout, read=call.read_timeout)
        try:
            reply = self._http.request(call.method, call.path, **kwargs)
        except httpx.TransportError as exc:
            raise Unreachable(None, f"{self.url}: {exc or type(exc).__name__}") from exc
        return _core.parse_reply(call, reply.status_code, reply.content)

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> ArmfleetClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- REST --------------------------------------------------------------------------------

    def info(self) -> Info:
        return self._call(_core.info_call())

    def state(self, world: int) -> WorldState:
        return self._call(_core.state_call(world))

    def states(self, worlds: WorldSpec = None) -> BatchStates:
        """Several worlds (None: all; or [0, 3], or "0-63") as column arrays."""
        return self._call(_core.states_call(worlds))

    def increment(self, world: int, joint: JointRef, delta: float) -> CommandAck:
        """Add `delta` [rad] to one joint's target (the seed's Up/Down buttons)."""
        return self._call(_core.increment_call(world, joint, delta))

    def set_targets(self, world: int, targets: Mapping[JointRef, float]) -> CommandAck:
        """Set some joints' targets, e.g. {"finger_joint": 0.7}; the others keep theirs."""
        return self._call(_core.set_targets_call(world, targets))

    def set_many(self, worlds: Iterable[int], positions: Any) -> BatchAck:
        """Full 7-joint targets for many worlds, applied at one tick; positions is (n, 7)."""
        return self._call(_core.set_many_call(worlds, positions))

    def reset(self, world: int | Iterable[int] | None = None) -> ResetResult:
        """Reset one world, a list of worlds, or (None) all worlds to home."""
        return self._call(_core.reset_call(world))

    def pause(self) -> SimStatus:
        return self._call(_core.pause_call())

    def resume(self) -> SimStatus:
        return self._call(_core.resume_call())

    def set_mode(self, mode: str) -> SimStatus:
        return self._call(_core.set_mode_call(mode))

    def step(self, n: int = 1) -> SimStatus:
        """Paused only: advance exactly n ticks; returns once they are done."""
        return self._call(_core.step_call(n))

    def ready(self) -> bool:
        try:
            self._call(_core.readyz_call())
        except (NotReady, Unreachable):
            return False
        return True

    def wait_ready(self, timeout: float = 60.0, poll: float = 0.2) -> None:
        """Block until /readyz says ready; NotReady (with the last reason) after `timeout`."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                self._call(_core.readyz_call())
                return
            except (NotReady, Unreachable) as exc:
                last = exc
            if time.monotonic() >= deadline:
                raise NotReady(last.status, last.detail, f"not ready after {timeout} s: {last}")
            time.sleep(poll)

    # -- WebSocket ---------------------------------------------------------------------------

    def stream(
        self,
        worlds: WorldSpec,
        rate: float | None = None,
        *,
        reconnect: bool = True,
        on_status: _core.StatusCallback | None = None,
        backoff: _core.Backoff | None = None,
        give_up_after: float | None = None,
        binary: bool = False,
    ) -> Iterator[Any]:
        """Yield states from the WebSocket: WorldState for one world (an int), BatchStates for
        a list / range string / None (all).

        When the connection drops (server restart, network), reconnect with backoff and go on;
        `on_status` hears about each drop and reconnect. `reconnect=False` raises Unreachable
        instead; `give_up_after` seconds of failing in a row raise it too. An unknown world
        raises NotFound at once. `binary=True` asks batch streams for float32 frames (same
        BatchStates, a fraction of the bytes and parse time).
        """
        url = _core.ws_url(self.url, worlds, rate, binary)
        policy = _core.Reconnector(url, reconnect, on_status, backoff, give_up_after)
        while True:
            try:
                with _open(url, self.timeout) as ws:
                    policy.opened()
                    for text in ws:
                        msg = policy.frame(text)
                        if msg is not None:
                            yield msg
                    reason = _core.close_reason(ws.close_code, ws.close_reason)
            except ConnectionClosed as exc:
                reason = _core.closed_exc_reason(exc)
            except _core.WS_DROPPED as exc:
                reason = _core.drop_reason(exc)
            time.sleep(policy.dropped(reason))

    def connect(self, world: int, rate: float | None = None) -> WorldSession:
        """Open a WebSocket to one world: send commands, get their acks, iterate states."""
        return WorldSession(_core.ws_url(self.url, world, rate), world, self.timeout)


def _open(url: str, timeout: float) -> ClientConnection:
    try:
        return ws_connect(url, open_timeout=timeout, max_size=_core.WS_MAX_SIZE, proxy=None)
    except InvalidURI as exc:
        raise ArmfleetError(None, str(exc)) from exc


class WorldSession:
    """One world over one WebSocket: commands get their acks back (matched by id) and state
    frames that arrive meanwhile are kept for iteration. Does not reconnect: a command on a
    dropped socket raises Unreachable. Use from one thread at a time (a lock enforces it).

        with client.connect(0) as s:
            ack = s.increment("elbow_joint", 0.1)
            for state in s: ...
    """

    def __init__(self, url: str, world: int, timeout: float = DEFAULT_TIMEOUT) -> None:
        self.url = url
        self.world = world
        self.timeout = timeout
        self._ids = _core.CommandIds()
        self._states: deque[WorldState] = deque(maxlen=256)
        self._lock = threading.Lock()
        try:
            self._ws = _open(url, timeout).__enter__()  # closed by close()
        except _core.WS_DROPPED as exc:
            raise Unreachable(None, f"{url}: {_core.drop_reason(exc)}") from exc
        self.latest: WorldState | None = None

    def _recv(self, timeout: float | None) -> Any:
        try:
            msg = _core.parse_ws(self._ws.recv(timeout))
        except ConnectionClosed as exc:
            raise Unreachable(None, f"{self.url}: {_core.closed_exc_reason(exc)}") from exc
        if isinstance(msg, WorldState):
            self.latest = msg
        return msg

    def _command(self, msg_id: int, text: str) -> CommandAck:
        with self._lock:
            try:
                self._ws.send(text)
            except ConnectionClosed as exc:
                raise Unreachable(None, f"{self.url}: {_core.closed_exc_reason(exc)}") from exc
            deadline = time.monotonic() + self.timeout
            while True:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no ack for command {msg_id} in {self.timeout} s")
                msg = self._recv(left)
                if isinstance(msg, WorldState):
                    self._states.append(msg)
                elif isinstance(msg, CommandAck | _core.WsError) and msg.id == msg_id:
                    return _core.ack_or_raise(msg)

    def increment(self, joint: JointRef, delta: float) -> CommandAck:
        return self._command(*self._ids.increment(joint, delta))

    def set_targets(self, targets: Mapping[JointRef, float]) -> CommandAck:
        return self._command(*self._ids.set_targets(targets))

    def reset(self) -> CommandAck:
        return self._command(*self._ids.reset())

    def recv_state(self, timeout: float | None = None) -> WorldState:
        """The next state frame (buffered ones first); TimeoutError after `timeout`."""
        with self._lock:
            if self._states:
                return self._states.popleft()
            deadline = None if timeout is None else time.monotonic() + timeout
            while True:
                left = None if deadline is None else max(0.0, deadline - time.monotonic())
                msg = self._recv(left)
                if isinstance(msg, WorldState):
                    return msg

    def __iter__(self) -> Iterator[WorldState]:
        while True:
            try:
                yield self.recv_state()
            except Unreachable:
                return

    def close(self) -> None:
        self._ws.close()

    def __enter__(self) -> WorldSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
