"""Foxglove live: what a Foxglove WebSocket client receives and what it may publish.

The client here speaks the protocol as the Foxglove app does (subprotocol `foxglove.sdk.v1` of
foxglove-sdk 0.30; JSON control frames, binary message frames), and decodes protobuf messages
from the schema the server advertises, so the test checks the wire, not our own encoder.
"""

from __future__ import annotations

import base64
import json
import struct
import time
from collections.abc import Iterator
from typing import Any

import httpx
import mujoco
import numpy as np
import pytest
from conftest import ELBOW, FINGER, Server, free_port, serve, wait_for
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from websockets.sync.client import ClientConnection, connect

from service.core.sim.robot import load_robot

NWORLD = 3
SUBPROTOCOL = "foxglove.sdk.v1"


@pytest.fixture(scope="module")
def fox(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, int]]:
    port = free_port()
    extra = ("--foxglove", "--foxglove-port", str(port), "--foxglove-worlds", "0-1")
    with serve(worlds=NWORLD, extra_args=extra, log_dir=tmp_path_factory.mktemp("fox")) as srv:
        yield srv, port


class FoxgloveClient:
    """The parts of the Foxglove WebSocket protocol a viewer uses."""

    def __init__(self, ws: ClientConnection):
        self.ws = ws
        self.channels: dict[str, dict[str, Any]] = {}
        self.statuses: list[dict[str, Any]] = []
        self.by_sub: dict[int, str] = {}

    def handshake(self) -> dict[str, Any]:
        info = json.loads(self.ws.recv(timeout=10))
        assert info["op"] == "serverInfo"
        while not {"/tf", "/scene"} <= set(self.channels):
            self._control(json.loads(self.ws.recv(timeout=10)))
        return info

    def _control(self, frame: dict[str, Any]) -> None:
        if frame["op"] == "advertise":
            self.channels.update({c["topic"]: c for c in frame["channels"]})
        elif frame["op"] == "status":
            self.statuses.append(frame)

    def subscribe(self, topics: list[str]) -> None:
        subs = []
        for i, topic in enumerate(topics):
            self.by_sub[i] = topic
            subs.append({"id": i, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def next_message(self, topic: str, timeout: float = 10) -> bytes:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            frame = self.ws.recv(timeout=timeout)
            if isinstance(frame, str):
                self._control(json.loads(frame))
                continue
            assert frame[0] == 0x01  # message data: sub id u32, log time u64, payload
            (sub,) = struct.unpack_from("<I", frame, 1)
            if self.by_sub.get(sub) == topic:
                return frame[13:]
        raise AssertionError(f"no message on {topic} in {timeout} s")

    def decoder(self, topic: str) -> Any:
        """A protobuf class for the channel, built from the schema the server advertised."""
        ch = self.channels[topic]
        assert ch["encoding"] == "protobuf" and ch["schemaEncoding"] == "protobuf"
        files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
        pool = descriptor_pool.DescriptorPool()
        for f in files.file:
            pool.Add(f)
        return message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))

    def advertise(self, channel_id: int, topic: str) -> None:
        self.ws.send(
            json.dumps(
                {
                    "op": "advertise",
                    "channels": [
                        {
                            "id": channel_id,
                            "topic": topic,
                            "encoding": "json",
                            "schemaName": "sensor_msgs/msg/JointState",
                        }
                    ],
                }
            )
        )

    def publish(self, channel_id: int, message: dict[str, Any]) -> None:
        self.ws.send(b"\x01" + struct.pack("<I", channel_id) + json.dumps(message).encode())


@pytest.fixture
def client(fox) -> Iterator[FoxgloveClient]:
    _, port = fox
    with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL]) as ws:
        c = FoxgloveClient(ws)
        info = c.handshake()
        assert "clientPublish" in info["capabilities"]
        yield c


def test_joint_states_per_shown_world_are_plottable_json(fox, client):
    srv, _ = fox
    shown = {t for t in client.channels if t.endswith("/joint_states")}
    assert shown == {"/world_0/joint_states", "/world_1/joint_states"}  # --foxglove-worlds 0-1
    ch = client.channels["/world_1/joint_states"]
    assert (ch["encoding"], ch["schemaName"]) == ("json", "sensor_msgs/msg/JointState")
    assert "position" in json.loads(ch["schema"])["properties"]
    client.subscribe(["/world_1/joint_states"])
    msg = json.loads(client.next_message("/world_1/joint_states"))
    assert msg["name"][ELBOW] == "elbow_joint" and len(msg["position"]) == 7
    served = httpx.get(f"{srv.url}/v1/worlds/1/state").json()
    np.testing.assert_allclose(msg["position"], served["position"], atol=0.05)


def test_frame_transforms_place_every_body_of_every_shown_world(client):
    client.subscribe(["/tf"])
    tf = client.decoder("/tf").FromString(client.next_message("/tf"))
    mjm = load_robot().mjm
    by_child = {t.child_frame_id: t for t in tf.transforms}
    for w in (0, 1):
        assert by_child[f"w{w}/world"].parent_frame_id == "world"
        for b in range(1, mjm.nbody):
            assert by_child[f"w{w}/{mjm.body(b).name}"].parent_frame_id == f"w{w}/world"
    assert len(tf.transforms) == 2 * mjm.nbody
    # Worlds stand apart in the shared frame; a fixed body sits where the model puts it.
    assert by_child["w1/world"].translation.x != by_child["w0/world"].translation.x or (
        by_child["w1/world"].translation.y != by_child["w0/world"].translation.y
    )
    base = by_child["w0/base"].translation
    data = mujoco.MjData(mjm)
    mujoco.mj_kinematics(mjm, data)
    base_id = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_BODY, "base")
    np.testing.assert_allclose([base.x, base.y, base.z], data.xpos[base_id], atol=1e-9)


def test_scene_update_draws_the_model_geoms_on_the_body_frames(client):
    client.subscribe(["/scene"])  # entities are (re)sent to a new subscriber
    scene = client.decoder("/scene").FromString(client.next_message("/scene"))
    frames = {e.frame_id for e in scene.entities}
    assert {"w0/base", "w0/wrist_3_link", "w1/cube", "w1/world"} <= frames
    assert all(e.frame_locked for e in scene.entities)
    cylinders = [c for e in scene.entities for c in e.cylinders]
    assert cylinders and all(c.bottom_scale == c.top_scale == 1.0 for c in cylinders)
    assert sum(len(e.cubes) for e in scene.entities if e.frame_id == "w0/cube") == 1


def test_published_joint_states_command_worlds_through_the_control_layer(fox, client):
    srv, _ = fox
    http = httpx.Client(base_url=srv.url, timeout=10)
    client.advertise(7, "/world_2/joint_commands")  # world 2 is commandable though not shown
    client.advertise(8, "/joint_commands")  # the seed's topic: world 0
    client.publish(7, {"name": ["elbow_joint", "finger_joint"], "position": [1.2, 0.5]})
    client.publish(8, {"name": ["elbow_joint"], "position": [9.0]})  # clamped like any command

    def targets() -> tuple[list[float], list[float]] | None:
        t2 = http.get("/v1/worlds/2/state").json()["target"]
        t0 = http.get("/v1/worlds/0/state").json()["target"]
        return (t2, t0) if t2[ELBOW] == 1.2 and t0[ELBOW] != HOME_ELBOW else None

    t2, t0 = wait_for(targets, "the published targets to apply")
    assert t2[FINGER] == 0.5
    assert t0[ELBOW] == pytest.approx(np.pi)  # clamped to the elbow's range


HOME_ELBOW = load_robot().spec.home[ELBOW]


def test_a_bad_published_message_gets_a_status_and_changes_nothing(fox, client):
    srv, _ = fox
    http = httpx.Client(base_url=srv.url, timeout=10)
    before = http.get("/v1/worlds/1/state").json()["target"]
    client.advertise(9, "/world_1/joint_commands")
    client.publish(9, {"name": ["elbow_joint", "nope_joint"], "position": [1.0, 2.0]})
    client.subscribe(["/world_0/joint_states"])
    deadline = time.monotonic() + 10
    while not client.statuses and time.monotonic() < deadline:
        client.next_message("/world_0/joint_states")
    assert client.statuses, "no status frame for a refused command"
    assert "nope_joint" in client.statuses[0]["message"]
    assert http.get("/v1/worlds/1/state").json()["target"] == before


def test_the_layout_in_docs_uses_what_the_server_offers(client):
    """docs/foxglove_layout.json: 3D on frame `world`, a plot of world 0, a publish panel."""
    from conftest import ROOT

    layout = json.loads((ROOT / "docs" / "foxglove_layout.json").read_text())
    panels = layout["configById"]
    assert {p.split("!")[0] for p in panels} == {"3D", "Plot", "Publish"}
    three_d = panels["3D!armfleet"]
    assert three_d["followTf"] == "world" and set(three_d["topics"]) <= set(client.channels)
    for path in panels["Plot!armfleet"]["paths"]:
        assert path["value"].split(".")[0] in client.channels
    publish = panels["Publish!armfleet"]
    assert publish["topicName"] == "/joint_commands"
    assert set(json.loads(publish["value"])) == {"name", "position"}


def test_with_a_token_publishes_need_it_as_a_parameter(tmp_path):
    """Foxglove's handshake cannot carry our token: a client presents it as the parameter
    `armfleet.token`; until then its publishes change nothing and a status says why."""
    port = free_port()
    extra = ("--foxglove", "--foxglove-port", str(port), "--token", "s3cret")
    with serve(worlds=1, extra_args=extra, log_dir=tmp_path) as srv:
        before = httpx.get(f"{srv.url}/v1/worlds/0/state").json()["target"]
        with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL]) as ws:
            c = FoxgloveClient(ws)
            assert {"clientPublish", "parameters"} <= set(c.handshake()["capabilities"])
            c.advertise(7, "/joint_commands")
            c.publish(7, {"name": ["elbow_joint"], "position": [0.5]})
            c.subscribe(["/world_0/joint_states"])  # it serves the viewer meanwhile
            c.next_message("/world_0/joint_states")
            assert httpx.get(f"{srv.url}/v1/worlds/0/state").json()["target"] == before
            assert any("armfleet.token" in s["message"] for s in c.statuses), c.statuses
            token = [{"name": "armfleet.token", "value": "s3cret"}]
            ws.send(json.dumps({"op": "setParameters", "id": "p", "parameters": token}))
            c.publish(7, {"name": ["elbow_joint"], "position": [0.5]})

            def moved() -> bool:
                target = httpx.get(f"{srv.url}/v1/worlds/0/state").json()["target"]
                return abs(target[ELBOW] - 0.5) < 1e-9

            wait_for(moved, "the publish with the token to apply")
