"""One JointState rule, one answer: the same bad messages fed to every surface that takes
JointState-shaped commands (HTTP, both WebSocket protocols, rosbridge, Foxglove) are refused
with the same words, the rule's (service.core.sim.rules.joint_state), and change nothing;
a nameless message of all seven positions is accepted by every one of them.

rosbridge and Foxglove frames are written by hand here as their clients put them on the wire
(test_rosbridge.py and test_foxglove.py judge those protocols with their real clients)."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from conftest import Server, free_port, serve, wait_for
from test_foxglove import SUBPROTOCOL, FoxgloveClient
from websockets.sync.client import connect

from service.core.sim.robot import load_robot
from service.core.sim.rules import BadJointState, joint_state

SPEC = load_robot().spec
# (name, position): each breaks the rule in its own way
BAD: list[tuple[list[Any], list[Any]]] = [
    (["elbow_joint"], []),
    (["elbow_joint", "finger_joint"], [0.3]),
    ([], [0.1, 0.2]),
    (["elbow"], [0.3]),
    (["elbow_joint", "elbow_joint"], [0.1, 0.2]),
    (["elbow_joint"], ["0.1"]),
    ([3], [0.1]),
]


def _rule(name: list[Any], position: list[Any]) -> str:
    with pytest.raises(BadJointState) as info:
        joint_state(SPEC, name, position)
    return str(info.value)


@pytest.fixture(scope="module")
def srv(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, int]]:
    port = free_port()
    extra = ("--foxglove", "--foxglove-port", str(port), "--foxglove-worlds", "0-1")
    with serve(worlds=2, extra_args=extra, log_dir=tmp_path_factory.mktemp("rule")) as server:
        yield server, port


def _targets(http: httpx.Client) -> list[list[float]]:
    return [http.get(f"/v1/worlds/{w}/state").json()["target"] for w in (0, 1)]


def _http(http: httpx.Client, name: list[Any], position: list[Any]) -> str:
    reply = http.put("/v1/worlds/1/targets", json={"name": name, "position": position})
    assert reply.status_code == 422, reply.text
    return " ".join(d["msg"] for d in reply.json()["detail"])


def _ws(ws: Any, name: list[Any], position: list[Any], **where: int) -> str:
    ws.send(json.dumps({"op": "set_targets", "id": 5, **where, "name": name, "position": position}))
    while True:
        frame = ws.recv(timeout=10)
        if isinstance(frame, str) and json.loads(frame).get("op") in ("ack", "error"):
            reply = json.loads(frame)
            assert reply["op"] == "error" and reply["id"] == 5, reply
            return reply["detail"]


def _rosbridge(ws: Any, name: list[Any], position: list[Any]) -> str:
    msg = {"name": name, "position": position}
    ws.send(json.dumps({"op": "publish", "id": "r", "topic": "/joint_commands", "msg": msg}))
    reply = json.loads(ws.recv(timeout=10))
    assert reply["op"] == "status" and reply["level"] == "error", reply
    return reply["msg"]


def _foxglove(client: FoxgloveClient, name: list[Any], position: list[Any]) -> str:
    seen = len(client.statuses)
    client.publish(9, {"name": name, "position": position})
    deadline = time.monotonic() + 10
    while len(client.statuses) == seen and time.monotonic() < deadline:
        client._control(json.loads(client.ws.recv(timeout=10)))
    assert len(client.statuses) > seen, "no status frame for a refused command"
    return client.statuses[-1]["message"]


def test_every_surface_refuses_each_bad_message_with_the_rules_words(srv) -> None:
    server, fox_port = srv
    http = httpx.Client(base_url=server.url, timeout=10)
    before = _targets(http)
    with (
        connect(server.ws_url + "/v1/ws?worlds=0") as batch,
        connect(server.ws_url + "/v1/ws/worlds/1") as single,
        connect(server.ws_url + "/v1/ws/view?focus=1") as view,
        connect(server.ws_url + "/rosbridge") as rosbridge,
        connect(f"ws://127.0.0.1:{fox_port}", subprotocols=[SUBPROTOCOL]) as fox,
    ):
        foxglove = FoxgloveClient(fox)
        foxglove.handshake()
        foxglove.advertise(9, "/world_1/joint_commands")
        for name, position in BAD:
            want = _rule(name, position)
            answers = {
                "http": _http(http, name, position),
                "ws": _ws(batch, name, position, world=1),
                "ws/worlds": _ws(single, name, position),
                "ws/view": _ws(view, name, position, world=1),
                "rosbridge": _rosbridge(rosbridge, name, position),
                "foxglove": _foxglove(foxglove, name, position),
            }
            for surface, answer in answers.items():
                assert want in answer, (surface, name, position, answer)
    assert _targets(http) == before


def test_a_nameless_message_of_every_joint_is_taken_everywhere(srv) -> None:
    server, fox_port = srv
    http = httpx.Client(base_url=server.url, timeout=10)
    row = [float(x) for x in SPEC.home]

    def nudged(i: int) -> list[float]:
        out = list(row)
        out[0] = 0.1 * i
        return out

    def lands(position: list[float], world: int = 1) -> None:
        wait_for(lambda: _targets(http)[world] == position, f"world {world}'s targets")

    assert http.put("/v1/worlds/1/targets", json={"position": nudged(1)}).status_code == 200
    lands(nudged(1))
    with connect(server.ws_url + "/v1/ws/worlds/1") as ws:
        ws.send(json.dumps({"op": "set_targets", "id": 1, "name": [], "position": nudged(2)}))
        lands(nudged(2))
    with connect(server.ws_url + "/rosbridge") as ws:
        msg = {"op": "publish", "topic": "/joint_commands", "msg": {"position": nudged(3)}}
        ws.send(json.dumps(msg))
        lands(nudged(3), world=0)
    with connect(f"ws://127.0.0.1:{fox_port}", subprotocols=[SUBPROTOCOL]) as fox:
        foxglove = FoxgloveClient(fox)
        foxglove.handshake()
        foxglove.advertise(9, "/world_1/joint_commands")
        foxglove.publish(9, {"position": nudged(4)})
        lands(nudged(4))
