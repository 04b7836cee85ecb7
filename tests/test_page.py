"""The browser page end to end: a real server, and Debian's Chromium driven by Playwright.

The first tests check what the page is built on (GET /, /v1/scene, the pose frames of
/v1/ws/view) with plain HTTP/WebSocket clients; the rest load the page in Chromium (software
WebGL) and use it as a person would: click its buttons, read what it shows, compare pixels.
"""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest
from conftest import JOINTS, free_port, running_server
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

NWORLD = 4


class RestartableServer:
    """A module's server on a fixed port, which one test kills and starts again."""

    def __init__(self, tmp_path) -> None:
        self.tmp_path = tmp_path
        self.port = free_port()
        self._cm = None
        self.server = None

    def start(self) -> None:
        self._cm = running_server(self.tmp_path, worlds=NWORLD, port=self.port)
        self.server = self._cm.__enter__()

    def stop(self) -> None:
        if self._cm is not None:
            cm, self._cm = self._cm, None
            cm.__exit__(None, None, None)

    @property
    def url(self) -> str:
        return self.server.url


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    holder = RestartableServer(tmp_path_factory.mktemp("page"))
    holder.start()
    yield holder
    holder.stop()


@pytest.fixture
def http(srv):
    with httpx.Client(base_url=srv.url, timeout=10) as client:
        client.post("/v1/sim/mode", json={"mode": "realtime"}).raise_for_status()
        client.post("/v1/reset").raise_for_status()
        yield client


def read_pose_frame(data: bytes) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray]:
    """Parse an AFP1 frame by the layout documented in service/wire.py."""
    assert data[:4] == b"AFP1"
    hlen = int.from_bytes(data[4:8], "little")
    assert hlen % 4 == 0
    header = json.loads(data[8 : 8 + hlen])
    n, nbody, at = header["n"], header["nbody"], 8 + hlen
    worlds = np.frombuffer(data, "<i4", n, at)
    faults = np.frombuffer(data, "<i4", n, at + 4 * n)
    poses = np.frombuffer(data, "<f4", n * nbody * 7, at + 8 * n).reshape(n, nbody, 7)
    assert len(data) == at + 8 * n + poses.nbytes
    return header, worlds, faults, poses


# ----------------------------------------------------------------- what the page is built on


def test_page_and_its_files_are_served_by_the_service(http):
    page = http.get("/")
    assert page.status_code == 200 and "text/html" in page.headers["content-type"]
    assert 'type="importmap"' in page.text and "/web/js/main.js" in page.text
    for path in ("/web/js/main.js", "/web/vendor/three/three.module.js", "/web/style.css"):
        r = http.get(path)
        assert r.status_code == 200 and len(r.content) > 100, path
    assert "three.js authors" in http.get("/web/vendor/three/LICENSE").text
    assert http.get("/web/nope.js").status_code == 404


def test_scene_route_describes_the_model_and_is_in_the_openapi_schema(http):
    scene = http.get("/v1/scene").json()
    assert scene["nbody"] == len(scene["bodies"]) == 19
    assert {b["name"] for b in scene["bodies"]} >= {"world", "pedestal", "cube", "gripper_base"}
    assert len(scene["geoms"]) > 20
    spec = http.get("/openapi.json").json()
    assert "/v1/scene" in spec["paths"] and "SceneGeom" in spec["components"]["schemas"]


def test_view_socket_sends_pose_frames_with_the_focus_worlds_state(srv, http):
    http.post("/v1/sim/pause").raise_for_status()
    http.put("/v1/worlds/2/targets", json={"name": ["elbow_joint"], "position": [1.0]})
    http.post("/v1/sim/step", json={"ticks": 30}).raise_for_status()
    state = http.get("/v1/worlds/2/state").json()
    scene = http.get("/v1/scene").json()
    nbody = scene["nbody"]
    gripper = next(b["id"] for b in scene["bodies"] if b["name"] == "gripper_base")
    with connect(f"{srv.server.ws_url}/v1/ws/view?worlds=0-3&focus=2&rate=30") as ws:
        header, worlds, faults, poses = read_pose_frame(ws.recv(timeout=5))
        # Commands go over the same socket, with ids, and are acknowledged.
        ws.send(json.dumps({"op": "increment", "world": 1, "joint": 0, "delta": 0.1, "id": 7}))
        ack = json.loads(ws.recv(timeout=5))
    assert ack["op"] == "ack" and ack["id"] == 7 and ack["target"][0] == pytest.approx(0.1)
    assert header["op"] == "poses" and header["tick"] == state["tick"]
    assert header["n"] == 4 and header["nbody"] == nbody and header["stats"]["mode"] == "paused"
    assert header["focus"]["world"] == 2 and header["focus"]["name"] == JOINTS
    assert header["focus"]["target"][2] == pytest.approx(1.0)
    assert header["focus"]["position"] == pytest.approx(state["position"], abs=1e-6)
    assert worlds.tolist() == [0, 1, 2, 3] and faults.tolist() == [0, 0, 0, 0]
    np.testing.assert_allclose(np.linalg.norm(poses[..., 3:], axis=2), 1.0, atol=1e-5)
    np.testing.assert_array_equal(poses[:, 0], np.tile([0, 0, 0, 1, 0, 0, 0], (4, 1)))
    # World 2 bent its elbow, the others are at home: only its arm is elsewhere.
    assert np.linalg.norm(poses[2, gripper, :3] - poses[0, gripper, :3]) > 0.05
    np.testing.assert_allclose(poses[1], poses[0], atol=1e-6)


@pytest.mark.parametrize(
    ("query", "needle"),
    [("worlds=0-9", "do not exist (0..3)"), ("focus=7", "world 7 does not exist"), ("", "give")],
)
def test_view_socket_refuses_what_does_not_exist_with_a_reason(srv, query, needle):
    with (
        connect(f"{srv.server.ws_url}/v1/ws/view?{query}") as ws,
        pytest.raises(ConnectionClosed) as closed,
    ):
        ws.recv(timeout=5)
    assert closed.value.rcvd.code == 1008 and needle in closed.value.rcvd.reason
