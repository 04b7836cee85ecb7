"""While paused, an accepted write is applied at once (issue 38 item 1): a read right after it
returns it, at the same tick, with no step, whatever surface wrote it (REST, the WebSocket op,
the Python client) and whatever it wrote (an entity's pose, a parameter, a reset, targets, a
randomisation); the reply's `tick` is still the first tick stepped from it. A recording of such
a session replays bit for bit, although replay stages each write for that tick instead: at a
tick boundary the two are the same state. A real server over real sockets (the ROS node's
SetEntityState is judged through real rclpy in tests/test_ros_node.py). The default engine
keeps float32: values compare within 1e-6."""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest
from conftest import running_server
from websockets.sync.client import connect

from clients import ArmfleetClient
from service.persistence.replay import read_recording, replay_recording

NWORLD = 4
SPEC = {"entities": {"cube": {"position": [[0.5, 0.7], [-0.1, 0.1], [0.9, 1.0]]}}}


def _cube(http: httpx.Client, world: int) -> dict:
    return http.get(f"/v1/worlds/{world}/entities/cube").json()


def test_paused_writes_are_instant_on_every_surface_and_replay_bit_for_bit(tmp_path):
    data = tmp_path / "data"
    extra = ("--data-dir", str(data), "--engine", "warp")
    with running_server(tmp_path, worlds=NWORLD, mode="paused", extra=extra) as srv:
        http = httpx.Client(base_url=srv.url, timeout=30)
        r = http.post("/v1/recordings", json={"name": "paused", "worlds": "0-3", "rate": 60})
        assert r.status_code == 201, r.text
        http.post("/v1/sim/step", json={"ticks": 4}).raise_for_status()
        tick = http.get("/v1/worlds/0/state").json()["tick"]

        # REST: an entity's pose, read back at once at the same tick
        ack = http.put("/v1/worlds/1/entities/cube", json={"position": [0.6, 0.05, 1.1]}).json()
        got = _cube(http, 1)
        assert ack["tick"] == tick + 1 and got["tick"] == tick
        assert got["position"] == pytest.approx([0.6, 0.05, 1.1], abs=1e-6)

        # the WebSocket op, read back over REST
        with connect(f"{srv.ws_url}/v1/ws") as ws:
            op = {"op": "set_entity", "world": 2, "name": "cube", "position": [0.55, 0, 1.05]}
            ws.send(json.dumps({**op, "id": 1}))
            while (frame := json.loads(ws.recv(timeout=10)))["op"] != "ack":
                pass
            assert frame["id"] == 1, frame
        assert _cube(http, 2)["position"] == pytest.approx([0.55, 0, 1.05], abs=1e-6)

        with ArmfleetClient(srv.url) as arm:
            # the Python client: an entity, a parameter, targets
            arm.set_entity(3, "cube", position=[0.65, -0.05, 1.0], linear=[0, 0, 0.5])
            cube = arm.entity(3, "cube")
            assert cube["position"] == pytest.approx([0.65, -0.05, 1.0], abs=1e-6)
            assert cube["linear"] == pytest.approx([0, 0, 0.5], abs=1e-6)
            arm.set_params(3, {"cube.mass": 0.25})
            assert arm.params(3)["params"]["cube.mass"] == pytest.approx(0.25, abs=1e-6)
            moved = arm.increment(0, "elbow_joint", 0.2)
            state = arm.state(0)
            assert state.tick == tick
            np.testing.assert_allclose(state.target, moved.target, atol=1e-6)
            # a reset puts the moved cube back home at once, where world 0's is
            arm.reset([0, 1])
            assert _cube(http, 1)["position"] == _cube(http, 0)["position"]
            assert _cube(http, 1)["position"] != pytest.approx([0.6, 0.05, 1.1], abs=1e-3)
            # a randomisation: drawn and in the state at once, named by the world's state
            drawn = http.post("/v1/randomize", json={"seed": 5, "spec": SPEC, "worlds": [2]})
            assert drawn.status_code == 200, drawn.text
            placed = _cube(http, 2)
            assert placed["tick"] == tick and 0.9 <= placed["position"][2] <= 1.0
            assert http.get("/v1/worlds/2/randomization").json()["seed"] == 5

        # still the same tick; then stepping goes on from the written state, and writes
        # between steps are instant too
        assert http.get("/v1/worlds/state").json()["tick"] == tick
        for i in range(6):
            http.post("/v1/sim/step", json={"ticks": 3}).raise_for_status()
            w = i % NWORLD
            http.put(f"/v1/worlds/{w}/entities/cube", json={"angular": [0, 0, 1.0 + i]})
            assert _cube(http, w)["angular"] == pytest.approx([0, 0, 1.0 + i], abs=1e-5)
        http.post("/v1/sim/step", json={"ticks": 4}).raise_for_status()
        done = http.delete("/v1/recordings/current")
        assert done.status_code == 200 and done.json()["error"] is None, done.text

    report = replay_recording(read_recording(data / "recordings" / "paused.mcap"))
    assert report.divergence is None, report.divergence
    assert report.commands >= 12 and report.states_compared > 0
    assert report.tolerance is None or pytest.fail(f"not compared bit for bit: {report}")
