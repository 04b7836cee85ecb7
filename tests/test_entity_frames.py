"""Entities in state frames, for the clients that ask (`entities=true`), over real sockets.

A paused native-MuJoCo server (float64 state, ticks counted exactly): the cube of world 1 is put
somewhere through the entity API, one tick is stepped, and the frames of that tick carry the
cube exactly as the entity API reads it at that tick, next to the joints of the same tick; a
subscriber that did not ask gets today's frames, without an `entities` field. A bad flag, or
entities asked with binary frames, is refused naming the field.
"""

from __future__ import annotations

import asyncio
import json
import math

import httpx
import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from clients import ArmfleetClient, AsyncArmfleetClient
from clients.stream import parse as parse_frame
from service.core.streams import entity_frames, frames, wire

S = math.sqrt(0.5)
POSE = {"position": [0.3, -0.5, 1.2], "orientation": [S, 0, 0, S]}
REST = {"linear": [0.0, 0.0, 0.0], "angular": [0.0, 0.0, 0.0]}


def _frame_at(ws, tick: int) -> dict:
    """The first state frame of `tick` or later (acks and status frames skipped)."""
    while True:
        msg = json.loads(ws.recv(timeout=10))
        if msg.get("op") in ("states", "state") and msg["tick"] >= tick:
            return msg


def _binary_at(ws, tick: int) -> tuple[dict, bytes]:
    """The first binary frame of `tick` or later: its header and what follows the rows."""
    while True:
        msg = ws.recv(timeout=10)
        if isinstance(msg, bytes):
            hlen = int.from_bytes(msg[4:8], "little")
            header = json.loads(msg[8 : 8 + hlen])
            if header["tick"] >= tick:
                width = sum(w for _, w in header["columns"])
                return header, msg[8 + hlen + 4 * header["n"] * (1 + width) :]


def _place_cube(http: httpx.Client, world: int) -> int:
    """Put world's cube at POSE, at rest; step one tick; that tick (the write's ack tick)."""
    ack = http.put(f"/v1/worlds/{world}/entities/cube", json=POSE | REST).json()
    stepped = http.post("/v1/sim/step", json={"ticks": 1}).json()
    assert stepped["tick"] == ack["tick"]
    return ack["tick"]


def test_batch_frames_carry_the_entities_of_their_tick_only_when_asked(paused):
    http = httpx.Client(base_url=paused.url, timeout=10)
    url = f"{paused.ws_url}/v1/ws?worlds=0-3"
    with (
        connect(f"{url}&entities=true") as with_entities,
        connect(url) as plain,
        connect(f"{url}&format=binary&entities=yes") as binary_entities,
        connect(f"{url}&format=binary") as binary_plain,
    ):
        first = _frame_at(with_entities, 0)
        assert first["entities"]["name"] == ["cube"]
        assert [len(first["entities"][k][0][0]) for k in ("position", "orientation")] == [3, 4]
        assert "entities" not in _frame_at(plain, 0)

        tick = _place_cube(http, 1)
        frame, other = _frame_at(with_entities, tick), _frame_at(plain, tick)
        assert frame["tick"] == other["tick"] == tick
        cube = http.get("/v1/worlds/1/entities/cube").json()
        assert cube["tick"] == tick
        ents = frame["entities"]
        row = frame["worlds"].index(1)
        got = {k: ents[k][row][0] for k in ("position", "orientation", "linear", "angular")}
        # exactly what the entity API reads at that tick (float64: the JSON text round-trips)
        assert got == {k: cube[k] for k in got}
        assert got["position"][:2] == POSE["position"][:2]  # one tick of free fall: z only
        assert got["orientation"] == pytest.approx(POSE["orientation"], abs=1e-15)
        assert got["position"][2] < POSE["position"][2]
        # the other worlds' cubes are where they were; the joints are the same tick's
        assert ents["position"][0][0] != got["position"]
        assert {k: v for k, v in frame.items() if k != "entities"} == other
        assert "entities" not in other
        # binary frames of the same selection, packed together: the block only where asked
        header, block = _binary_at(binary_entities, tick)
        assert header["tick"] == tick and header["entities"]["name"] == ["cube"]
        values = np.frombuffer(block[: 4 * 13 * 4], "<f4").reshape(4, 1, 13)
        assert block[4 * 13 * 4 :] == bytes([1] * 4)  # layout 2: then each world's safety mode
        np.testing.assert_array_equal(values[row, 0, :3], np.float32(got["position"]))
        header, rest = _binary_at(binary_plain, tick)
        assert header["tick"] == tick and "entities" not in header
        assert rest == bytes([1] * 4)  # only the safety block (layout 2): every world NORMAL

        # the REST state read, asked likewise, reports the same tick's entities
        state = http.get("/v1/worlds/1/state", params={"entities": "true"}).json()
        assert state["tick"] == tick and state["entities"] == [{"name": "cube", **got}]
        assert "entities" not in http.get("/v1/worlds/1/state").json()
        rows = http.get("/v1/worlds/state", params={"worlds": "1", "entities": "1"}).json()
        assert rows["worlds"][0]["entities"] == state["entities"]


def test_a_single_world_socket_carries_its_entities(paused):
    http = httpx.Client(base_url=paused.url, timeout=10)
    with connect(f"{paused.ws_url}/v1/ws/worlds/2?entities=true") as ws:
        assert [e["name"] for e in _frame_at(ws, 0)["entities"]] == ["cube"]
        tick = _place_cube(http, 2)
        frame = _frame_at(ws, tick)
    cube = http.get("/v1/worlds/2/entities/cube").json()
    assert frame["tick"] == cube["tick"] == tick
    assert frame["entities"] == [{k: cube[k] for k in frame["entities"][0]}]
    with connect(f"{paused.ws_url}/v1/ws/worlds/2") as ws:
        assert "entities" not in _frame_at(ws, 0)


@pytest.mark.parametrize(
    ("query", "words"),
    [
        ("ws/worlds/1?entities=maybe", "'maybe' is not a flag"),
        ("ws?entities=2", "'2' is not a flag"),
        ("ws?format=binary&entities=on%20", "'on ' is not a flag"),
    ],
)
def test_a_bad_entities_option_is_refused_naming_the_field(paused, query, words):
    with connect(f"{paused.ws_url}/v1/{query}") as ws, pytest.raises(ConnectionClosed) as exc:
        ws.recv(timeout=10)
    assert exc.value.rcvd is not None and exc.value.rcvd.code == 1008
    assert "query.entities" in exc.value.rcvd.reason and words in exc.value.rcvd.reason


def test_a_bad_entities_flag_over_http_is_a_422_naming_it(paused):
    reply = httpx.get(f"{paused.url}/v1/worlds/1/state", params={"entities": "maybe"})
    assert reply.status_code == 422 and '"entities"' in reply.text


def test_the_python_clients_stream_and_read_entities(paused):
    tick = _place_cube(httpx.Client(base_url=paused.url, timeout=10), 3)
    with ArmfleetClient(paused.url) as arm:
        cube = arm.entity(3, "cube")
        states = arm.states([1, 3], entities=True)
        assert states.tick == tick and states.entities is not None
        assert states.entities.name == ("cube",)
        assert states.world(3).entities.position[0].tolist() == cube["position"]
        one = arm.state(3, entities=True)
        assert one.entities.orientation[0].tolist() == cube["orientation"]
        assert arm.state(3).entities is None
        batch = next(arm.stream([3], entities=True, reconnect=False))
        assert batch.entities.position.shape == (1, 1, 3)
        assert batch.entities.position[0, 0].tolist() == cube["position"]
        # binary frames: the same values as float32, the joints' columns as before
        fast = next(arm.stream([1, 3], entities=True, binary=True, reconnect=False))
        assert fast.tick == tick and fast.entities.name == ("cube",)
        np.testing.assert_array_equal(
            fast.entities.position[1, 0], np.float32(cube["position"]).astype(np.float64)
        )
        np.testing.assert_array_equal(fast.position, np.float32(states.position))
        assert next(arm.stream([3], binary=True, reconnect=False)).entities is None
        with arm.connect(3, entities=True) as session:
            assert session.recv_state(timeout=10).entities.linear[0].tolist() == cube["linear"]
        single = next(arm.stream(3, entities=True, reconnect=False))
        assert single.entities.linear[single.entities.index("cube")].tolist() == cube["linear"]
        assert next(arm.stream([3], reconnect=False)).entities is None

    async def run() -> None:
        async with AsyncArmfleetClient(paused.url) as arm:
            one = await arm.state(3, entities=True)
            assert one.entities.position[0].tolist() == cube["position"]
            stream = arm.stream("3", entities=True, reconnect=False)
            got = await anext(stream)
            await stream.aclose()
            assert got.entities.angular[0, 0].tolist() == cube["angular"]

    asyncio.run(run())


def _engine(name: str):
    if name == "mujoco":
        from service.engines.native import NativeBatch

        return NativeBatch(4, nthread=1)
    from service.engines.warp import WorldBatch

    return WorldBatch(4, device=name.removeprefix("warp-"), capture=False)


def _engines() -> list[str]:
    import warp as wp

    return ["mujoco", "warp-cpu", *(["warp-cuda"] if wp.is_cuda_available() else [])]


@pytest.mark.parametrize("engine", _engines())
def test_packed_frames_with_entities_are_the_snapshot_frames_byte_for_byte(engine):
    """The sim thread's packed frame (frames.JSON_ENTITIES) and the one rendered from a
    snapshot that carries entities are the same bytes, on either engine's dtype."""
    batch = _engine(engine)
    try:
        batch.step(5)  # the cube has settled a little: non-trivial twists
        ids, names = np.array([1, 3]), batch.spec.names
        data = frames.pack(batch, ids, json=True)
        assert data is not None
        data.entities = entity_frames.read(batch, ids)
        rows = data.packed.wait()
        try:
            snap = entity_frames.attach(batch.snapshot(), batch)
            packed = frames.json_entities(data, rows, names)
            assert packed == wire.batch_frame(snap, ids, names, None, entities=True)
            assert frames.json(data, rows, names) == wire.batch_frame(snap, ids, names)
            binary = frames.binary_entities(data, rows, names)
            assert binary == wire.batch_frame_binary(snap, ids, names, entities=True)
            assert frames.binary(data, rows, names) == wire.batch_frame_binary(snap, ids, names)
        finally:
            data.packed.release()
        doc = json.loads(packed)
        qpos = batch.qpos()
        adr = batch.robot.mjm.jnt_qposadr[batch.robot.mjm.joint("cube_joint").id]
        parsed = parse_frame(binary).entities  # the client's reading of the binary block
        for i, w in enumerate(ids):
            got = doc["entities"]["position"][i][0] + doc["entities"]["orientation"][i][0]
            np.testing.assert_array_equal(np.array(got, qpos.dtype), qpos[w, adr : adr + 7])
            pose = np.concatenate((parsed.position[i, 0], parsed.orientation[i, 0]))
            np.testing.assert_array_equal(pose, qpos[w, adr : adr + 7].astype(np.float32))
    finally:
        batch.close()


def test_big_frames_with_entities_go_through_the_helper_process_unchanged(monkeypatch):
    """A big JSON frame with entities is serialised in a helper process like one without; the
    four formats of one selection come out as the snapshot's frames, byte for byte."""
    import queue

    from service.engines.native import NativeBatch

    monkeypatch.setattr(frames, "BIG_JSON_ROWS", 2)
    batch = NativeBatch(4, nthread=1)
    batch.step(3)
    ids, names = np.array([0, 2, 3]), batch.spec.names
    got: queue.Queue = queue.Queue()
    sender = frames.FrameSender(lambda job, out: got.put(out))
    formats = ["binary", "binary+entities", "json", "json+entities"]
    try:
        data = frames.pack(batch, ids, json=True)
        assert data is not None
        data.entities = entity_frames.read(batch, ids)
        sender.submit(frames.Job(data, formats, None, names))
        out: dict = {}
        while len(out) < len(formats):  # each format is delivered when it is ready
            out.update(got.get(timeout=60))
    finally:
        sender.stop()
        snap = entity_frames.attach(batch.snapshot(), batch)
        batch.close()
    assert out["json"] == wire.batch_frame(snap, ids, names)
    assert out["json+entities"] == wire.batch_frame(snap, ids, names, None, entities=True)
    assert out["binary"] == wire.batch_frame_binary(snap, ids, names)
    assert out["binary+entities"] == wire.batch_frame_binary(snap, ids, names, entities=True)
