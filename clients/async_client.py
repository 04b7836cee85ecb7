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
from collections.abc import AsyncIterator, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import httpx
from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect

from clients import calls, cartesian, cell, models, stream
from clients import trajectory as tj
from clients.calls import DEFAULT_TIMEOUT, Call
from clients.errors import ArmfleetError, Unreachable, unreachable
from clients.models import JointRef, WorldSpec

if TYPE_CHECKING:  # typing has both from 3.11 on; the client also runs on 3.10
    from typing_extensions import Self, Unpack


class _Closes:
    """`async with thing:` closes the thing at the end."""

    async def close(self) -> None:
        raise NotImplementedError

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


class AsyncArmfleetClient(_Closes, cartesian.AsyncCalls, calls.Endpoint):
    """REST + WebSocket client for one armfleet service, for asyncio."""

    HTTP = httpx.AsyncClient

    async def call(self, call: Call) -> Any:
        kwargs = call.request_kwargs(self.timeout)
        try:
            reply = await self._http.request(call.method, call.path, **kwargs)
        except httpx.TransportError as exc:
            raise calls.transport_error(self.url, exc) from exc
        return call.result(reply)

    async def close(self) -> None:
        await self._http.aclose()

    # -- REST (docstrings on the sync twin) --------------------------------------------------

    async def info(self) -> models.Info:
        return await self.call(calls.info_call())

    async def state(self, world: int, entities: bool = False) -> models.WorldState:
        return await self.call(calls.state_call(world, entities))

    async def states(self, worlds: WorldSpec = None, entities: bool = False) -> models.BatchStates:
        return await self.call(calls.states_call(worlds, entities))

    async def increment(self, world: int, joint: JointRef, delta: float) -> models.CommandAck:
        return await self.call(calls.increment_call(world, joint, delta))

    async def set_targets(self, world: int, targets: Mapping[JointRef, float]) -> models.CommandAck:
        return await self.call(calls.set_targets_call(world, targets))

    async def set_many(self, worlds: Iterable[int], positions: Any) -> models.BatchAck:
        return await self.call(calls.set_many_call(worlds, positions))

    async def reset(self, world: int | Iterable[int] | None = None) -> models.ResetResult:
        return await self.call(calls.reset_call(world))

    async def trigger_protective_stop(self, world: int) -> models.SafetyAck:
        return await self.call(calls.trigger_protective_stop_call(world))

    async def unlock_protective_stop(self, world: int) -> models.SafetyAck:
        return await self.call(calls.unlock_protective_stop_call(world))

    # -- entities and physics parameters (as ArmfleetClient's ----------------------------

    async def entities(self, world: int) -> dict[str, Any]:
        return await self.call(cell.entities_call(world))

    async def entity(self, world: int, name: str) -> dict[str, Any]:
        return await self.call(cell.entity_call(world, name))

    async def set_entity(self, world: int, name: str, **values: Any) -> dict[str, Any]:
        return await self.call(cell.set_entity_call(world, name, **values))

    async def set_entities(self, writes: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
        return await self.call(cell.set_entities_call(writes))

    async def param_table(self) -> dict[str, Any]:
        return await self.call(cell.param_table_call())

    async def params(self, world: int) -> dict[str, Any]:
        return await self.call(cell.params_call(world))

    async def set_params(self, world: int, params: Mapping[str, Any]) -> dict[str, Any]:
        return await self.call(cell.set_params_call(world, params))

    async def set_params_many(
        self, writes: Iterable[tuple[int, Mapping[str, Any]]]
    ) -> dict[str, Any]:
        return await self.call(cell.set_params_many_call(writes))

    async def randomize(
        self, seed: int, spec: Mapping[str, Any], worlds: Iterable[int] | None = None
    ) -> dict[str, Any]:
        return await self.call(cell.randomize_call(seed, spec, worlds))

    async def randomization(self, world: int) -> dict[str, Any]:
        return await self.call(cell.randomization_call(world))

    # -- trajectories: as ArmfleetClient's -------------------------------------------------

    async def start_trajectory(
        self, world: int, joint_names: Sequence[str], points: Iterable[Any], **options: Any
    ) -> tj.TrajectoryStarted:
        body = tj.trajectory_body(joint_names, points, **options)
        return await self.call(tj.start_call(world, body))

    async def start_trajectories(
        self, worlds: WorldSpec, joint_names: Sequence[str], points: Iterable[Any], **options: Any
    ) -> tj.TrajectoriesStarted:
        body = tj.trajectory_body(joint_names, points, **options)
        return await self.call(tj.start_many_call(worlds, body))

    async def trajectory(self, world: int, wait: float = 0.0) -> tj.TrajectoryStatus:
        return await self.call(tj.status_call(world, wait))

    async def cancel_trajectory(self, world: int) -> tj.TrajectoryStatus:
        return await self.call(tj.cancel_call(world))

    async def wait_trajectory(
        self, traj_id: int, timeout: float | None = None
    ) -> tj.TrajectoryStatus:
        wait = tj.OutcomeWait(traj_id, timeout)
        while not wait.finished(status := await self.call(wait.call())):
            pass
        return status

    async def follow_trajectory(
        self,
        world: int,
        joint_names: Sequence[str],
        points: Iterable[Any],
        timeout: float | None = None,
        **options: Any,
    ) -> tj.TrajectoryStatus:
        started = await self.start_trajectory(world, joint_names, points, **options)
        return await self.wait_trajectory(started.id, timeout)

    async def pause(self) -> models.SimStatus:
        return await self.call(calls.pause_call())

    async def resume(self) -> models.SimStatus:
        return await self.call(calls.resume_call())

    async def set_mode(self, mode: str) -> models.SimStatus:
        return await self.call(calls.set_mode_call(mode))

    async def step(self, n: int = 1) -> models.SimStatus:
        return await self.call(calls.step_call(n))

    async def ready(self) -> bool:
        try:
            await self.call(calls.readyz_call())
        except calls.NOT_YET:
            return False
        return True

    async def wait_ready(self, timeout: float = 60.0, poll: float = 0.2) -> None:
        wait = calls.ReadyWait(timeout)
        while True:
            try:
                await self.call(calls.readyz_call())
                return
            except calls.NOT_YET as exc:
                wait.failed(exc)
            await asyncio.sleep(poll)

    async def leases(self) -> list[models.Lease]:
        return await self.call(calls.leases_call())

    async def renew_lease(self, ttl_s: float = 600.0) -> models.Lease:
        if self.leased is None:
            raise ValueError("this client holds no lease (use `async with client.lease() as c:`)")
        return await self.call(calls.renew_call(self.leased.id, ttl_s))

    # -- WebSocket ---------------------------------------------------------------------------

    async def stream(
        self,
        worlds: WorldSpec,
        rate: float | None = None,
        **options: Unpack[stream.StreamOptions],
    ) -> AsyncIterator[Any]:
        """Async twin of `ArmfleetClient.stream` (same arguments, same reconnect rules)."""
        policy = stream.Reconnector.for_stream(self.url, worlds, rate, options)
        while True:
            try:
                async with await _open(policy.url, self.timeout, self.token) as ws:
                    policy.opened()
                    async for text in ws:
                        if (msg := policy.frame(text)) is not None:
                            yield msg
                    reason = stream.close_reason(ws.close_code, ws.close_reason)
            except stream.LOST as exc:
                reason = stream.reason_for(exc)
            await asyncio.sleep(policy.dropped(reason))

    async def connect(
        self, world: int, rate: float | None = None, entities: bool = False
    ) -> AsyncWorldSession:
        """Open a WebSocket to one world (`async with await client.connect(0) as s:`);
        `entities=True`: its states carry the world's entities."""
        url = stream.ws_url(self.url, world, rate, entities=entities)
        session = AsyncWorldSession(url, world, self.timeout, self.token)
        await session.open()
        return session


async def _open(url: str, timeout: float, token: str | None = None) -> ClientConnection:
    with stream.bad_url():
        return await ws_connect(url, **stream.connect_options(timeout, token))


class AsyncWorldSession(_Closes, stream.WorldLink, cartesian.AsyncWorldOps):
    """One world over one WebSocket. A reader task routes acks to their commands (by id), so
    several tasks may send commands at once; state frames queue up for iteration (the oldest
    are dropped past 256)."""

    def __init__(
        self, url: str, world: int, timeout: float = DEFAULT_TIMEOUT, token: str | None = None
    ) -> None:
        super().__init__(url, world, timeout, token)
        self._pending: dict[int, asyncio.Future[models.CommandAck]] = {}
        self._states: asyncio.Queue[models.WorldState | None] = asyncio.Queue(maxsize=256)
        self._ws: ClientConnection | None = None
        self._reader: asyncio.Task[None] | None = None
        self._error: ArmfleetError | None = None

    async def open(self) -> None:
        try:
            self._ws = await _open(self.url, self.timeout, self.token)
        except stream.DROPPED as exc:
            raise stream.lost(self.url, exc) from exc
        self._reader = asyncio.create_task(self._read())

    def _route(self, msg: stream.WsMessage | None) -> None:
        """A state to the queue (dropping the oldest when full), an ack to its command."""
        if isinstance(msg, models.WorldState):
            self.latest = msg
            self._offer(msg)
        elif isinstance(msg, models.CommandAck | models.WsError):
            fut = self._pending.pop(msg.id, None)
            if fut is None or fut.done():
                return
            try:
                fut.set_result(stream.ack_or_raise(msg))
            except ArmfleetError as exc:
                fut.set_exception(exc)

    def _offer(self, item: models.WorldState | None) -> None:
        if self._states.full():
            self._states.get_nowait()
        self._states.put_nowait(item)

    async def _read(self) -> None:
        assert self._ws is not None
        try:
            async for text in self._ws:
                self._route(stream.parse(text))
            why = stream.close_reason(self._ws.close_code, self._ws.close_reason)
            self._error = unreachable(self.url, why)
        except ArmfleetError as exc:  # NotFound: the server refused this world for good
            self._error = exc
        except stream.LOST as exc:
            try:
                self._error = stream.lost(self.url, exc)
            except ArmfleetError as err:
                self._error = err
        finally:
            err = self._error or unreachable(self.url, "closed")
            for fut in self._pending.values():
                if not fut.done():
                    fut.set_exception(err)
            self._pending.clear()
            self._offer(None)  # wakes an iterator: the socket is gone

    async def _command(self, msg_id: int, text: str) -> models.CommandAck:
        if self._ws is None or self._error is not None:
            raise self._error or unreachable(self.url, "not open")
        fut: asyncio.Future[models.CommandAck] = asyncio.get_running_loop().create_future()
        self._pending[msg_id] = fut
        try:
            await self._ws.send(text)
        except stream.LOST as exc:
            self._pending.pop(msg_id, None)
            raise unreachable(self.url, stream.drop_reason(exc)) from exc
        try:
            return await asyncio.wait_for(fut, self.timeout)
        finally:
            self._pending.pop(msg_id, None)

    async def increment(self, joint: JointRef, delta: float) -> models.CommandAck:
        return await self._command(*self._ids.increment(joint, delta))

    async def set_targets(self, targets: Mapping[JointRef, float]) -> models.CommandAck:
        return await self._command(*self._ids.set_targets(targets))

    async def reset(self) -> models.CommandAck:
        return await self._command(*self._ids.reset())

    async def recv_state(self, timeout: float | None = None) -> models.WorldState:
        """The next state frame; Unreachable once the socket is gone."""
        state = await asyncio.wait_for(self._states.get(), timeout)
        if state is None:
            self._states.put_nowait(None)
            raise self._error or unreachable(self.url, "closed")
        return state

    def __aiter__(self) -> AsyncIterator[models.WorldState]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[models.WorldState]:
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
