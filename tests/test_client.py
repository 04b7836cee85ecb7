"""The client library end to end, sync and async, against a real `armfleet serve`."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import ELBOW, FINGER, HOME, JOINTS, Server, free_port, serve

from clients import (
    ArmfleetClient,
    ArmfleetError,
    AsyncArmfleetClient,
    Backoff,
    BatchStates,
    CommandRejected,
    Conflict,
    ConnectionStatus,
    InvalidRequest,
    NotFound,
    NotReady,
    Unreachable,
    WorldState,
)


class _Blocking:
    """The async client behind the sync client's call style (one event loop for its life), so
    one test body checks both twins."""

    def __init__(self, url: str) -> None:
        self.loop = asyncio.new_event_loop()
        self.client = self.loop.run_until_complete(self._make(url))

    @staticmethod
    async def _make(url: str) -> AsyncArmfleetClient:
        return AsyncArmfleetClient(url, timeout=10)

    def __getattr__(self, name: str) -> Callable[..., Any]:
        method = getattr(self.client, name)
        return lambda *a, **k: self.loop.run_until_complete(method(*a, **k))

    def shutdown(self) -> None:
        self.loop.run_until_complete(self.client.close())
        self.loop.close()


def state_at(api: Any, world: int, tick: int) -> WorldState:
    """The world's state once `tick` (a command's reply tick) has been stepped: a command takes
    effect at the next tick boundary, and GET state shows the last completed tick."""
    deadline = time.monotonic() + 5
    while (state := api.state(world)).tick < tick:
        assert time.monotonic() < deadline, f"tick {tick} not reached (at {state.tick})"
        time.sleep(0.02)
    return state


@pytest.fixture(params=["sync", "async"])
def api(request: pytest.FixtureRequest, server: Server) -> Iterator[Any]:
    if request.param == "sync":
        with ArmfleetClient(server.url, timeout=10) as client:
            yield client
    else:
        wrapped = _Blocking(server.url)
        yield wrapped
        wrapped.shutdown()


@pytest.fixture
def client(server: Server) -> Iterator[ArmfleetClient]:
    with ArmfleetClient(server.url, timeout=10) as c:
        yield c


# -- REST --------------------------------------------------------------------------------------


def test_info_describes_the_robot_joints_and_world_count(api: Any) -> None:
    info = api.info()
    assert info.names == JOINTS
    assert info.nworld == 4
    assert info.mode == "realtime"
    finger = info.joints[FINGER]
    assert (finger.lower, finger.upper) == (0.0, pytest.approx(0.7))
    assert [j.home for j in info.joints] == pytest.approx(HOME)
    assert info.home == pytest.approx(HOME)
    assert info.joint("elbow_joint") is info.joints[ELBOW]
    assert info.shards >= 1


def _fields(cls: Any) -> set[str]:
    return set(getattr(cls, "model_fields", None) or cls.__dataclass_fields__)


def test_client_models_follow_the_server_schemas() -> None:
    """Every reply field the server documents is a field of the client's result type (the
    client's Info once lacked `shards`): a field added on one side only fails here."""
    from clients import models
    from service.core.contract import replies as schemas

    pairs = [
        (models.Info, schemas.Info, set()),
        (models.CommandAck, schemas.CommandReply, {"id"}),  # id: WebSocket acks only
        (models.BatchAck, schemas.BatchCommandReply, set()),
        (models.ResetResult, schemas.ResetReply, set()),
        (models.SimStatus, schemas.SimReply, set()),
        (models.SafetyAck, schemas.TriggerReply, set()),
        (models.SafetyAck, schemas.UnlockReply, {"why"}),  # why: a trigger's only
    ]
    for ours, theirs, extra in pairs:
        assert _fields(ours) - extra == _fields(theirs), ours.__name__
    assert models.JointInfo is schemas.JointSpec  # one joint description, not a copy
    flange = {f"flange_{k}" for k in _fields(schemas.Flange)}
    assert _fields(models.WorldState) == _fields(schemas.WorldState) - {"flange"} | flange


def test_the_async_client_has_the_sync_clients_face() -> None:
    """Every public call of ArmfleetClient is one of AsyncArmfleetClient with the same
    parameters and defaults, awaited (a call added to one twin only fails here); the lending
    block (`lease`, `lent`) is shared from calls.Endpoint."""
    import inspect

    def face(cls: type) -> dict[str, list[tuple[str, Any, Any]]]:
        return {
            name: [(p.name, p.default, p.kind) for p in inspect.signature(f).parameters.values()]
            for name, f in inspect.getmembers(cls, inspect.isfunction)
            if not name.startswith("_")
        }

    sync, asyn = face(ArmfleetClient), face(AsyncArmfleetClient)
    assert sync == asyn
    assert {"trigger_protective_stop", "unlock_protective_stop", "reset"} <= set(sync)
    shared = {"lease", "lent"}  # calls.Endpoint's, for both
    for name in set(asyn) - shared:
        f = getattr(AsyncArmfleetClient, name)
        assert inspect.iscoroutinefunction(f) or inspect.isasyncgenfunction(f), name


def test_state_holds_seven_joints_and_the_flange_pose(api: Any) -> None:
    state = state_at(api, 3, api.reset(3).tick)
    assert isinstance(state, WorldState)
    assert state.world == 3 and state.tick > 0
    assert list(state.name) == JOINTS
    for arr in (state.position, state.velocity, state.effort, state.target):
        assert isinstance(arr, np.ndarray) and arr.shape == (7,)
    assert state.target == pytest.approx(HOME)
    assert state.flange_position.shape == (3,)
    assert np.linalg.norm(state.flange_quaternion) == pytest.approx(1.0, abs=1e-4)


def test_increments_accumulate_and_the_finger_clamps_at_both_limits(api: Any) -> None:
    api.reset(0)
    first = api.increment(0, "elbow_joint", 0.1)
    second = api.increment(0, ELBOW, 0.1)
    assert first.target[ELBOW] == pytest.approx(1.67)
    assert second.target[ELBOW] == pytest.approx(1.77)
    assert second.tick >= first.tick
    acks = [api.increment(0, "finger_joint", 0.1) for _ in range(9)]
    assert [round(a.target[FINGER], 6) for a in acks] == [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7] + [
        0.7
    ] * 2
    assert acks[-1].clamped == ("finger_joint",)
    assert acks[0].clamped == ()
    down = [api.increment(0, "finger_joint", -0.1) for _ in range(9)]
    assert down[-1].target[FINGER] == 0.0
    assert down[-1].clamped == ("finger_joint",)
    assert state_at(api, 0, down[-1].tick).target[FINGER] == 0.0


def test_set_targets_changes_only_the_named_joints(api: Any) -> None:
    api.reset(1)
    ack = api.set_targets(1, {"elbow_joint": 1.2, FINGER: 0.35})
    expected = list(HOME)
    expected[ELBOW], expected[FINGER] = 1.2, 0.35
    assert ack.target == pytest.approx(expected)
    clamped = api.set_targets(1, {"finger_joint": 5.0})
    assert clamped.target[FINGER] == pytest.approx(0.7)
    assert clamped.clamped == ("finger_joint",)
    assert state_at(api, 1, clamped.tick).target == pytest.approx(expected[:FINGER] + [0.7])


def test_reset_returns_the_world_to_home_targets(api: Any) -> None:
    api.set_targets(2, {"shoulder_pan_joint": 1.0})
    one = api.reset(2)
    assert one.worlds == (2,)
    assert state_at(api, 2, one.tick).target == pytest.approx(HOME)
    everything = api.reset()
    assert everything.worlds == (0, 1, 2, 3)
    assert everything.tick >= one.tick


def test_states_returns_arrays_with_one_row_per_world(api: Any) -> None:
    api.reset()
    tick = api.set_many([0, 3], [HOME[:6] + [0.2], HOME[:6] + [0.4]]).tick
    state_at(api, 0, tick)
    batch = api.states([0, 3])
    assert isinstance(batch, BatchStates)
    assert batch.worlds.tolist() == [0, 3]
    assert batch.position.shape == (2, 7) and batch.flange_quaternion.shape == (2, 4)
    assert batch.target[:, FINGER] == pytest.approx([0.2, 0.4])
    assert batch.world(3).target[FINGER] == pytest.approx(0.4)
    assert len(api.states()) == 4
    assert api.states("1-2").worlds.tolist() == [1, 2]


def test_set_many_applies_all_rows_at_one_tick(api: Any) -> None:
    rows = np.tile(HOME, (4, 1))
    rows[:, ELBOW] = [0.5, 0.6, 0.7, 0.8]
    result = api.set_many(range(4), rows)
    assert result.worlds.tolist() == [0, 1, 2, 3]
    assert result.target[:, ELBOW] == pytest.approx([0.5, 0.6, 0.7, 0.8])
    assert {r.tick for r in result.results} == {result.tick}
    api.reset()


def test_errors_raise_typed_exceptions_carrying_the_server_detail(api: Any) -> None:
    with pytest.raises(NotFound) as missing:
        api.state(9)
    assert missing.value.status == 404
    assert missing.value.detail == "world 9 does not exist (0..3)"
    with pytest.raises(InvalidRequest) as bad_joint:
        api.increment(0, "bogus_joint", 0.1)
    assert bad_joint.value.status == 422
    assert "unknown joint 'bogus_joint'" in bad_joint.value.detail[0]["msg"]
    assert "bogus_joint" in str(bad_joint.value)
    with pytest.raises(InvalidRequest):
        api.increment(0, "elbow_joint", 100.0)  # |delta| over 2π
    with pytest.raises(Conflict) as not_paused:
        api.step(1)
    assert "paused" in not_paused.value.detail
    assert isinstance(not_paused.value, ArmfleetError)


def test_step_advances_exactly_n_ticks_while_paused(api: Any) -> None:
    paused = api.pause()
    try:
        assert paused.mode == "paused"
        before = api.state(0).tick
        time.sleep(0.1)
        assert api.state(0).tick == before  # time stands still
        stepped = api.step(7)
        assert stepped.tick == before + 7
        assert api.state(0).tick == before + 7
        assert api.set_mode("fast").mode == "fast"
    finally:
        assert api.resume().mode == "realtime"
    assert api.info().mode == "realtime"


def test_wait_ready_returns_for_a_ready_server(api: Any) -> None:
    api.wait_ready(5)
    assert api.ready() is True


def test_unreachable_server_raises_unreachable() -> None:
    url = f"http://127.0.0.1:{free_port()}"
    with ArmfleetClient(url, timeout=2) as c:
        with pytest.raises(Unreachable) as err:
            c.info()
        assert err.value.status is None
        assert c.ready() is False
        with pytest.raises(NotReady, match="Connection refused"):
            c.wait_ready(0.3, poll=0.05)
        with pytest.raises(Unreachable):
            next(iter(c.stream(0, reconnect=False)))


# -- WebSocket ---------------------------------------------------------------------------------


def test_stream_yields_states_with_increasing_ticks(client: ArmfleetClient) -> None:
    ticks = []
    for state in client.stream(1, rate=30):
        assert isinstance(state, WorldState) and state.world == 1
        ticks.append(state.tick)
        if len(ticks) == 5:
            break
    assert ticks == sorted(ticks) and len(set(ticks)) == 5


def test_async_stream_yields_states_with_increasing_ticks(server: Server) -> None:
    async def collect() -> list[int]:
        ticks: list[int] = []
        async with AsyncArmfleetClient(server.url) as c:
            async for state in c.stream(2, rate=30):
                assert state.world == 2
                ticks.append(state.tick)
                if len(ticks) == 5:
                    break
        return ticks

    ticks = asyncio.run(collect())
    assert ticks == sorted(ticks) and len(set(ticks)) == 5


def test_batch_stream_yields_arrays_for_the_listed_worlds(client: ArmfleetClient) -> None:
    frames = []
    for frame in client.stream([1, 3], rate=30):
        assert isinstance(frame, BatchStates)
        frames.append(frame)
        if len(frames) == 3:
            break
    assert all(f.worlds.tolist() == [1, 3] for f in frames)
    assert frames[-1].position.shape == (2, 7)
    assert [f.tick for f in frames] == sorted({f.tick for f in frames})


def test_stream_of_an_unknown_world_raises_not_found(client: ArmfleetClient) -> None:
    with pytest.raises(NotFound, match="world 9 does not exist"):
        next(iter(client.stream(9)))


def test_websocket_commands_get_their_acks(client: ArmfleetClient) -> None:
    client.reset(3)
    with client.connect(3, rate=30) as session:
        up = session.increment("elbow_joint", 0.1)
        assert up.id == 1 and up.world == 3
        assert up.target[ELBOW] == pytest.approx(1.67)
        grip = session.set_targets({"finger_joint": 0.7})
        assert grip.id == 2 and grip.target[FINGER] == pytest.approx(0.7)
        with pytest.raises(CommandRejected, match="unknown joint"):
            session.increment("nope", 0.1)
        # the socket stays usable after an error, and states keep coming
        again = session.increment(ELBOW, -0.1)
        assert again.target[ELBOW] == pytest.approx(1.57)
        later = [session.recv_state(5) for _ in range(3)]
        assert all(s.world == 3 for s in later)
        home = session.reset()
        assert home.target == pytest.approx(HOME)
    assert state_at(client, 3, home.tick).target == pytest.approx(HOME)


def test_recv_state_times_out_with_timeout_error_and_the_socket_stays_usable(
    client: ArmfleetClient,
) -> None:
    with client.connect(1, rate=0.2) as session:  # a frame at connect, the next in 5 s
        session.recv_state(10)
        with pytest.raises(TimeoutError, match="no message"):
            session.recv_state(0.3)
        assert session.increment(FINGER, 0.0).world == 1  # not Unreachable: still connected


def test_async_websocket_commands_in_parallel_get_their_own_acks(server: Server) -> None:
    async def drive() -> list[float]:
        async with AsyncArmfleetClient(server.url) as c:
            await c.reset(2)
            async with await c.connect(2) as session:
                acks = await asyncio.gather(*(session.increment(FINGER, 0.1) for _ in range(5)))
                assert sorted(a.id for a in acks) == [1, 2, 3, 4, 5]
                with pytest.raises(CommandRejected):
                    await session.set_targets({"finger_joint": float("nan")})
                state = await session.recv_state(5)
                assert state.world == 2
                await session.reset()
                return sorted(round(a.target[FINGER], 6) for a in acks)

    assert asyncio.run(drive()) == [0.1, 0.2, 0.3, 0.4, 0.5]


def test_stream_reconnects_after_the_server_restarts(
    tmp_path: Path,
) -> None:
    """Sync and async streams ride out a server stop/start on the same port."""
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    stop = threading.Event()
    seen: dict[str, list[Any]] = {"sync": [], "async": []}

    def sync_reader() -> None:
        with ArmfleetClient(url, timeout=2) as c:
            backoff = Backoff(first=0.05, maximum=0.3)
            for state in c.stream(0, rate=30, on_status=seen["sync"].append, backoff=backoff):
                seen["sync"].append(state)
                if stop.is_set():
                    return

    def async_reader() -> None:
        async def read() -> None:
            async with AsyncArmfleetClient(url, timeout=2) as c:
                backoff = Backoff(first=0.05, maximum=0.3)
                async for state in c.stream(
                    0, rate=30, on_status=seen["async"].append, backoff=backoff
                ):
                    seen["async"].append(state)
                    if stop.is_set():
                        return

        asyncio.run(read())

    def wait_for(pred: Callable[[], bool], what: str, timeout: float = 30) -> None:
        deadline = time.monotonic() + timeout
        while not pred():
            assert time.monotonic() < deadline, f"timed out waiting for {what}: {seen}"
            time.sleep(0.05)

    def n_states(kind: str) -> int:
        return sum(isinstance(x, WorldState) for x in seen[kind])

    readers = [threading.Thread(target=f, daemon=True) for f in (sync_reader, async_reader)]
    try:
        with serve(worlds=1, port=port, log_dir=tmp_path) as first:
            assert first.url == url
            for t in readers:
                t.start()
            wait_for(lambda: n_states("sync") >= 3 and n_states("async") >= 3, "first frames")
        wait_for(
            lambda: all(
                any(isinstance(x, ConnectionStatus) and not x.connected for x in seen[k])
                for k in seen
            ),
            "the drop to be reported",
        )
        before = {k: n_states(k) for k in seen}
        with serve(worlds=1, port=port, log_dir=tmp_path):
            wait_for(
                lambda: all(n_states(k) >= before[k] + 3 for k in seen), "frames after restart"
            )
            stop.set()
            for t in readers:
                t.join(timeout=5)
    finally:
        stop.set()
    for kind, events in seen.items():
        statuses = [e for e in events if isinstance(e, ConnectionStatus)]
        assert statuses[0].connected, kind
        assert any(not s.connected for s in statuses), kind
        assert statuses[-1].connected, kind  # back up after the restart
        assert not any(t.is_alive() for t in readers)


def test_binary_batch_stream_yields_the_same_batch_states(server):
    from clients import ArmfleetClient

    with ArmfleetClient(server.url) as arm:
        stream = arm.stream([0, 2], binary=True)
        batch = next(stream)
        stream.close()
        assert batch.worlds.tolist() == [0, 2] and batch.position.shape == (2, 7)
        assert batch.world(2).target == pytest.approx(arm.state(2).target, abs=1e-6)
