"""Asynchronous twin of `clients.client`: `AsyncArmfleetClient` and `AsyncWorldSession`.

Same methods, awaited:

    async with AsyncArmfleetClient("http://127.0.0.1:8000") as arm:
        await arm.wait_ready(60)
        await arm.increment(0, "elbow_joint", 0.1)
        async for state in arm.stream(0, rate=10):
            print(state.tick, state.position)
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Iterable, Mapping
from typing import Any

import httpx
from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import ConnectionClosed, InvalidURI

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


class AsyncArmfleetClient:
    """REST + WebSocket client for one armfleet service, for asyncio."""

    def __init__(self, url: str = DEFAULT_URL, timeout: float = DEFAULT_TIMEOUT) -> None:
        self.url = url.rstrip("/")
        self.timeout = timeout
        self._http = httpx.AsyncClient(base_url=self.url, timeout=timeout)

    # -- plumbing ----------------------------------------------------------------------------

    async def _call(self, call: Call) -> Any:
        kwargs: dict[str, Any] = {"params": call.params, "json": call.json}
        if call.read_timeout is not False:
            kwargs["timeout"] = httpx.Timeout(self.timeout, read=call.read_timeout)
        try:
            reply = await self._http.request(call.method, call.path, **kwargs)
        except httpx.TransportError as exc:
            raise Unreachable(None, f"{self.url}: {exc or type(exc).__name__}") from exc
        return _core.parse_reply(call, reply.status_code, reply.content)

    async def close(self) -> None:
        await self._http.aclose()

    async def __aenter__(self) -> AsyncArmfleetClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- REST --------------------------------------------------------------------------------

    async def info(self) -> Info:
        return await self._call(_core.info_call())

    async def state(self, world: int) -> WorldState:
        return await self._call(_core.state_call(world))

    async def states(self, worlds: WorldSpec = None) -> BatchStates:
        return await self._call(_core.states_call(worlds))

    async def increment(self, world: int, joint: JointRef, delta: float) -> CommandAck:
        return await self._call(_core.increment_call(world, joint, delta))

    async def set_targets(self, world: int, targets: Mapping[JointRef, float]) -> CommandAck:
        return await self._call(_core.set_targets_call(world, targets))

    async def set_many(self, worlds: Iterable[int], positions: Any) -> BatchAck:
        return await self._call(_core.set_many_call(worlds, positions))

    async def reset(self, world: int | Iterable[int] | None = None) -> ResetResult:
        return await self._call(_core.reset_call(world))

    async def pause(self) -> SimStatus:
        return await self._call(_core.pause_call())

    async def resume(self) -> SimStatus:
        return await self._call(_core.resume_call())

    async def set_mode(self, mode: str) -> SimStatus:
        return await self._call(_core.set_mode_call(mode))

    async def step(self, n: int = 1) -> SimStatus:
        return await self._call(_core.step_call(n))

    async def ready(self) -> bool:
        try:
            await self._call(_core.readyz_call())
        except (NotReady, Unreachable):
            return False
        return True

    async def wait_ready(self, timeout: float = 60.0, poll: float = 0.2) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                await self._call(_core.readyz_call())
                return
            except (NotReady, Unreachable) as exc:
                last = exc
            if time.monotonic() >= deadline:
                raise NotReady(last.status, last.detail, f"not ready after {timeout} s: {last}")
            await asyncio.sleep(poll)

    # -- WebSocket ---------------------------------------------------------------------------

    async def stream(
        self,
        worlds: WorldSpec,
        rate: float | None = None,
        *,
        reconnect: bool = True,
        on_status: _core.StatusCallback | None = None,
        backoff: _core.Backoff | None = None,
        give_up_after: float | None = None,
        binary: bool = False,
    ) -> AsyncIterator[Any]:
        """Async twin of `ArmfleetClient.stream` (same arguments, same reconnect rules)."""
        url = _core.ws_url(self.url, worlds, rate, binary)
        policy = _core.Reconnector(url, reconnect, on_status, backoff, give_up_after)
        while True:
            try:
                async with await _open(url, self.timeout) as ws:
                    policy.opened()
                    async for text in ws:
                        msg = policy.frame(text)
                        if msg is not None:
                            yield msg
                    reason = _core.close_reason(ws.close_code, ws.close_reason)
            except ConnectionClosed as exc:
                reason = _core.closed_exc_reason(exc)
            except _core.WS_DROPPED as exc:
                reason = _core.drop_reason(exc)
            await asyncio.sleep(policy.dropped(reason))

    async def connect(self, world: int, rate: float | None = None) -> AsyncWorldSession:
        """Open a WebSocket to one world (`async with await client.connect(0) as s:`)."""
        session = AsyncWorldSession(_core.ws_url(self.url, world, rate), world, self.timeout)
        await session.open()
        return session


async def _open(url: str, timeout: float) -> ClientConnection:
    try:
        return await ws_connect(url, open_timeout=timeout, max_size=_core.WS_MAX_SIZE, proxy=None)
    except InvalidURI as exc:
        raise ArmfleetError(None, str(exc)) from exc


class AsyncWorldSession:
    """One world over one WebSocket. A reader task routes acks to their commands (by id), so
    several tasks may send commands at once; state frames queue up for iteration (the oldest
    are dropped past 256)."""

    def __init__(self, url: str, world: int, timeout: float = DEFAULT_TIMEOUT) -> None:
        self.url = url
        self.world = world
        self.timeout = timeout
        self.latest: WorldState | None = None
        self._ids = _core.CommandIds()
        self._pending: dict[int, asyncio.Future[CommandAck]] = {}
        self._states: asyncio.Queue[WorldState | None] = asyncio.Queue(maxsize=256)
        self._ws: ClientConnection | None = None
        self._reader: asyncio.Task[None] | None = None
        self._error: ArmfleetError | None = None

    async def open(self) -> None:
        try:
            self._ws = await _open(self.url, self.timeout)
        except _core.WS_DROPPED as exc:
            raise Unreachable(None, f"{self.url}: {_core.drop_reason(exc)}") from exc
        self._reader = asyncio.create_task(self._read())

    async def _read(self) -> None:
        assert self._ws is not None
        try:
            async for text in self._ws:
                msg = _core.parse_ws(text)
                if isinstance(msg, WorldState):
                    self.latest = msg
                    if self._states.full():
                        self._states.get_nowait()
                    self._states.put_nowait(msg)
                elif isinstance(msg, CommandAck | _core.WsError):
                    fut = self._pending.pop(msg.id, None)
                    if fut is not None and not fut.done():
                        if isinstance(msg, _core.WsError):
                            fut.set_exception(_core.CommandRejected(None, msg.detail))
                        else:
                            fut.set_result(msg)
            self._error = Unreachable(
                None,
                f"{self.url}: {_core.close_reason(self._ws.close_code, self._ws.close_reason)}",
            )
        except ArmfleetError as exc:
            self._error = exc
        except ConnectionClosed as exc:
            try:
                self._error = Unreachable(None, f"{self.url}: {_core.closed_exc_reason(exc)}")
            except ArmfleetError as err:
                self._error = err
        finally:
            err = self._error or Unreachable(None, f"{self.url}: closed")
            for fut in self._pending.values():
                if not fut.done():
                    fut.set_exception(err)
            self._pending.clear()
            if self._states.full():
                self._states.get_nowait()
            self._states.put_nowait(None)  # wakes an iterator: the socket is gone

    async def _command(self, msg_id: int, text: str) -> CommandAck:
        if self._ws is None or self._error is not None:
            raise self._error or Unreachable(None, f"{self.url}: not open")
        fut: asyncio.Future[CommandAck] = asyncio.get_running_loop().create_future()
        self._pending[msg_id] = fut
        try:
            await self._ws.send(text)
        except ConnectionClosed as exc:
            self._pending.pop(msg_id, None)
            raise Unreachable(None, f"{self.url}: {_core.drop_reason(exc)}") from exc
        try:
            return await asyncio.wait_for(fut, self.timeout)
        finally:
            self._pending.pop(msg_id, None)

    async def increment(self, joint: JointRef, delta: float) -> CommandAck:
        return await self._command(*self._ids.increment(joint, delta))

    async def set_targets(self, targets: Mapping[JointRef, float]) -> CommandAck:
        return await self._command(*self._ids.set_targets(targets))

    async def reset(self) -> CommandAck:
        return await self._command(*self._ids.reset())

    async def recv_state(self, timeout: float | None = None) -> WorldState:
        """The next state frame; Unreachable once the socket is gone."""
        state = await asyncio.wait_for(self._states.get(), timeout)
        if state is None:
            self._states.put_nowait(None)
            raise self._error or Unreachable(None, f"{self.url}: closed")
        return state

    def __aiter__(self) -> AsyncIterator[WorldState]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[WorldState]:
        while True:
            try:
                yield await self.recv_state()
            except Unreachable:
                return

    async def close(self) -> None:
        if self._ws is not None:
            await self._ws.close()
        if self._reader is not None:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._reader

    async def __aenter__(self) -> AsyncWorldSession:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
