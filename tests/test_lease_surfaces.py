"""A lease token on every surface: its own world answers, another world is refused (a 403-like
error naming the world, with the command's id where the protocol has one) and nothing changes,
as the administrator reads every world before and after, bit for bit.

Judges: a WebSocket client (the world socket, the batch socket, and the page's view socket with
the token as a subprotocol, as the page sends it), roslibpy on rosbridge, and a Foxglove
WebSocket client (tests/test_foxglove.py's, speaking foxglove.sdk.v1) presenting the token as
the parameter `armfleet.token`. The server is paused, so any change at all would show.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
import roslibpy
from websockets.sync.client import ClientConnection, connect

from tests.conftest import JOINTS, Server, free_port, serve, wait_for
from tests.test_foxglove import SUBPROTOCOL, FoxgloveClient

ADMIN = "admin-" + "k" * 26
MINE, OTHER = 1, 0  # world 0 also has the seed's plain topics (/joint_commands)


@pytest.fixture(scope="module")
def surfaces(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, int, str]]:
    fox = free_port()
    extra = (
        "--token", ADMIN, "--leases", "optional", "--engine", "mujoco", "--ros2-worlds", "1",
        "--foxglove", "--foxglove-port", str(fox), "--foxglove-worlds", "0-1",
    )  # fmt: skip
    log_dir = tmp_path_factory.mktemp("lease-surfaces")
    with serve(worlds=4, mode="paused", extra_args=extra, log_dir=log_dir) as srv:
        r = httpx.post(
            f"{srv.url}/v1/leases",
            json={"worlds": [MINE], "ttl_s": 600, "label": "surfaces"},
            headers={"Authorization": f"Bearer {ADMIN}"},
        )
        assert r.status_code == 201, r.text
        yield srv, fox, r.json()["token"]


def everything(server: Server) -> Any:
    """Every world's state (paused: pending targets included) as the administrator reads it."""
    r = httpx.get(f"{server.url}/v1/worlds/state", headers={"Authorization": f"Bearer {ADMIN}"})
    return r.json()


def target(server: Server, world: int) -> list[float]:
    """The world's targets as of every accepted command (paused: not yet in effect)."""
    return httpx.get(f"{server.url}/v1/worlds/{world}/state").json()["pending_target"]


def forbidden(server: Server, source: str) -> float:
    for line in httpx.get(f"{server.url}/metrics").text.splitlines():
        if line.startswith(f'armfleet_forbidden_total{{source="{source}"}}'):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


def reply(ws: ClientConnection, msg_id: Any) -> dict[str, Any]:
    """The JSON reply to our message `msg_id` (state frames, binary or not, skipped)."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        frame = ws.recv(timeout=10)
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg.get("id") == msg_id and msg.get("op") in ("ack", "error"):
                return msg
    raise AssertionError(f"no reply to {msg_id}")


SOCKETS = {
    "world socket": (f"/v1/ws/worlds/{OTHER}", None, "ws"),
    "batch socket": ("/v1/ws?worlds=0-3", OTHER, "ws"),
    "page's view socket": (f"/v1/ws/view?worlds=0-1&focus={MINE}", OTHER, "browser"),
}


@pytest.mark.parametrize("name", list(SOCKETS))
def test_websockets_refuse_another_world_with_an_error_frame(
    surfaces: tuple[Server, int, str], name: str
) -> None:
    server, _, token = surfaces
    path, world, source = SOCKETS[name]
    if name == "page's view socket":  # the page's way: a subprotocol, never in the URL
        how: dict[str, Any] = {"subprotocols": ["armfleet", f"armfleet.token.{token}"]}
    else:
        how = {"additional_headers": {"Authorization": f"Bearer {token}"}}
    before, count = everything(server), forbidden(server, source)
    with connect(f"{server.ws_url}{path}", **how) as ws:
        where = {} if world is None else {"world": world}
        ws.send(
            json.dumps({"op": "increment", "joint": "elbow_joint", "delta": 0.3, "id": 41, **where})
        )
        err = reply(ws, 41)
        assert err["op"] == "error" and f"world {OTHER} is not in this lease" in err["detail"], err
        ops = [
            {"op": "set_targets", "name": ["elbow_joint"], "position": [1.0]},
            {"op": "reset"},
            {"op": "trajectory", "joint_names": ["elbow_joint"],
             "points": [{"positions": [0.5], "time_from_start": 1}]},
        ]  # fmt: skip
        for i, op in enumerate(ops):
            ws.send(json.dumps({**op, "id": f"x{i}", **where}))
            assert reply(ws, f"x{i}")["op"] == "error"
        assert everything(server) == before  # nothing changed, anywhere
        if world is not None:  # the same socket commands the lease's own world
            ws.send(json.dumps({"op": "increment", "joint": "elbow_joint", "delta": 0.1,
                                "id": 42, "world": MINE}))  # fmt: skip
            assert reply(ws, 42)["op"] == "ack"
    assert forbidden(server, source) == count + 4


def test_rosbridge_via_roslibpy_refuses_another_world(surfaces: tuple[Server, int, str]) -> None:
    server, _, token = surfaces
    ros = roslibpy.Ros("127.0.0.1", server.port, headers={"Authorization": f"Bearer {token}"})
    ros.run(timeout=20)
    try:
        before, count = everything(server), forbidden(server, "rosbridge")
        theirs = roslibpy.Topic(ros, "/joint_commands", "sensor_msgs/msg/JointState")
        theirs.publish(roslibpy.Message({"name": ["elbow_joint"], "position": [1.1]}))
        wait_for(lambda: forbidden(server, "rosbridge") == count + 1, "the refusal")
        assert everything(server) == before
        rejected = httpx.get(f"{server.url}/v1/ros").json()["rosbridge"]["rejected"]
        assert rejected.get("forbidden", 0) >= 1, rejected
        mine = roslibpy.Topic(ros, f"/world_{MINE}/joint_commands", "sensor_msgs/msg/JointState")
        mine.publish(roslibpy.Message({"name": ["elbow_joint"], "position": [1.1]}))
        elbow = JOINTS.index("elbow_joint")
        wait_for(lambda: abs(target(server, MINE)[elbow] - 1.1) < 1e-9, "its own world to move")
    finally:
        ros.close()
    # the protocol's error frame: a status naming the world, with the publish's id
    with connect(
        f"{server.ws_url}/rosbridge", additional_headers={"Authorization": f"Bearer {token}"}
    ) as ws:
        ws.send(json.dumps({"op": "advertise", "topic": "/joint_commands",
                            "type": "sensor_msgs/msg/JointState"}))  # fmt: skip
        ws.send(json.dumps({"op": "publish", "id": "p1", "topic": "/joint_commands",
                            "msg": {"name": ["elbow_joint"], "position": [0.2]}}))  # fmt: skip
        status = json.loads(ws.recv(timeout=10))
        assert status["op"] == "status" and status["id"] == "p1", status
        assert f"world {OTHER} is not in this lease" in status["msg"], status


def test_foxglove_refuses_another_world_and_never_echoes_the_token(
    surfaces: tuple[Server, int, str],
) -> None:
    server, port, token = surfaces
    with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL]) as ws:
        client, seen = FoxgloveClient(ws), []
        info = client.handshake()
        assert {"clientPublish", "parameters"} <= set(info["capabilities"])
        client.advertise(5, "/joint_commands")  # world 0: not ours
        client.publish(5, {"name": ["elbow_joint"], "position": [1.3]})  # no token yet
        present = [{"name": "armfleet.token", "value": token}]
        ws.send(json.dumps({"op": "setParameters", "id": "t", "parameters": present}))
        before, count = everything(server), forbidden(server, "foxglove")
        client.publish(5, {"name": ["elbow_joint"], "position": [1.3]})
        client.advertise(6, f"/world_{MINE}/joint_commands")
        client.publish(6, {"name": ["elbow_joint"], "position": [0.7]})
        elbow = JOINTS.index("elbow_joint")
        wait_for(lambda: abs(target(server, MINE)[elbow] - 0.7) < 1e-9, "its own world to move")
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and len(client.statuses) < 2:
            frame = ws.recv(timeout=30)
            seen.append(frame)
            if isinstance(frame, str):
                client._control(json.loads(frame))
        messages = [s["message"] for s in client.statuses]
        assert any("armfleet.token" in m for m in messages), messages  # tokenless: told how
        assert any(f"world {OTHER} is not in this lease" in m for m in messages), messages
        after = everything(server)
        assert forbidden(server, "foxglove") == count + 1
        assert _without_world(after, MINE) == _without_world(before, MINE)
        assert not any(token in f for f in seen if isinstance(f, str))
        assert not any(token.encode() in f for f in seen if isinstance(f, bytes))


def _without_world(states: dict[str, Any], world: int) -> dict[str, Any]:
    """A states reply without the row of `world` (the one the lease may move)."""
    return {**states, "worlds": [row for row in states["worlds"] if row["world"] != world]}
