"""Seeded randomisation: the same seed gives bit-identical worlds on either CPU engine, another
seed other worlds; over HTTP and the WebSocket the ack holds the seed and the spec; a range
reaching outside a limit is refused before anything is drawn."""

from __future__ import annotations

import json
from types import SimpleNamespace

import httpx
import numpy as np
import pytest
from websockets.sync.client import connect

from bench.cells import SPEC  # the spec the cells bench draws for 10,000 worlds
from clients.testing import serve
from service.core.commands.randomize import Randomize
from service.core.sim.batch import TickWrites


def _batch(engine: str, nworld: int):
    if engine == "mujoco":
        from service.engines.native import NativeBatch

        return NativeBatch(nworld, nthread=1)
    from service.engines.warp import WorldBatch

    # captured, as served: an uncaptured tick cost ~30 ms of CPU (4-6 worlds) against ~1.5 ms,
    # a capture ~0.2 s (test_engine.py holds captured and uncaptured ticks bit-identical)
    return WorldBatch(nworld)


def _apply(batch, seed: int, worlds=None) -> None:
    door = SimpleNamespace(loop=SimpleNamespace(batch=batch), nworld=batch.nworld, spec=batch.spec)
    cmd = Randomize.create(door, worlds, seed, SPEC)
    batch.write(
        TickWrites(
            resets=np.array(cmd.worlds),
            model=cmd.params.writes,
            state=cmd.entities.writes,
        )
    )
    batch.step(20)


@pytest.mark.parametrize("engine", ["mujoco", "warp"])
def test_the_same_seed_gives_bit_identical_worlds(engine):
    a, b, c = (_batch(engine, 4) for _ in range(3))
    _apply(a, 7)
    _apply(b, 7)
    _apply(c, 8)
    np.testing.assert_array_equal(a.qpos(), b.qpos())
    np.testing.assert_array_equal(a.model_values("body_mass"), b.model_values("body_mass"))
    assert not np.array_equal(a.qpos(), c.qpos())
    cube = a.robot.mjm.jnt_qposadr[a.robot.mjm.joint("cube_joint").id]
    assert len({round(float(x), 6) for x in a.qpos()[:, cube]}) == 4  # every world its own
    # a world's draw depends on the seed and its id only: world 2 alone draws the same
    d = _batch(engine, 4)
    _apply(d, 7, [2])
    np.testing.assert_array_equal(d.qpos()[2], a.qpos()[2])


def test_http_and_websocket_randomize_with_the_seed_and_spec_in_the_ack(paused):
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        ack = http.post("/v1/randomize", json={"seed": 3, "spec": SPEC}).json()
        assert ack["worlds"] == [0, 1, 2, 3] and ack["seed"] == 3 and ack["spec"] == SPEC
        http.post("/v1/sim/step", json={"ticks": 1})
        masses = [
            http.get(f"/v1/worlds/{w}/params").json()["params"]["cube.mass"] for w in range(4)
        ]
        assert len(set(masses)) == 4 and all(0.05 <= m <= 0.5 for m in masses)
        bad = {"seed": 3, "spec": {"params": {"cube.mass": [0, 1]}}}
        reply = http.post("/v1/randomize", json=bad)
        assert reply.status_code == 422 and "reaches outside 0.001..100 kg" in reply.text
        bad = {"seed": 3, "spec": {"entities": {"cube": {"position": [[0, 1], [0, 1], [0, 9]]}}}}
        reply = http.post("/v1/randomize", json=bad)
        assert reply.status_code == 422 and "outside the scene's bounds" in reply.text
        # a yaw range too wide to draw from (its width overflowed to inf: was a 500)
        bad = {"seed": 3, "spec": {"entities": {"cube": {"yaw": [-1e308, 1e308]}}}}
        reply = http.post("/v1/randomize", json=bad)
        assert reply.status_code == 422, reply.text
        assert reply.json()["detail"][0]["loc"] == ["body", "spec", "entities", "cube", "yaw"]
        again = http.post("/v1/randomize", json={"seed": 3, "spec": SPEC, "worlds": [1]}).json()
        http.post("/v1/sim/step", json={"ticks": 1})
        assert http.get("/v1/worlds/1/params").json()["params"]["cube.mass"] == masses[1]
        assert again["worlds"] == [1]
    with connect(f"{paused.ws_url}/v1/ws/worlds/2") as ws:
        ws.send(json.dumps({"op": "randomize", "id": 4, "seed": 3, "spec": SPEC}))
        while (msg := json.loads(ws.recv(timeout=5)))["op"] not in ("ack", "error"):
            pass
    assert msg["op"] == "ack" and msg["seed"] == 3 and msg["spec"] == SPEC


def test_a_recording_holds_the_seed_and_spec_and_replays_bit_for_bit(tmp_path):
    from mcap.reader import make_reader

    from service.persistence.replay import replay

    data = tmp_path / "data"
    extra = ("--data-dir", str(data), "--engine", "warp")  # replay steps the warp engine
    with serve(worlds=4, mode="paused", extra_args=extra, log_dir=tmp_path) as srv:
        http = httpx.Client(base_url=srv.url, timeout=60)
        assert http.post("/v1/recordings", json={"name": "rand", "rate": 60}).status_code == 201
        http.post("/v1/sim/step", json={"ticks": 5}).raise_for_status()
        http.post("/v1/randomize", json={"seed": 11, "spec": SPEC}).raise_for_status()
        http.post("/v1/sim/step", json={"ticks": 20}).raise_for_status()
        put = {"position": [0.3, -0.5, 1.0], "linear": [0.5, 0, 0]}
        http.put("/v1/worlds/1/entities/cube", json=put).raise_for_status()
        http.put("/v1/worlds/2/params", json={"params": {"payload": [2, 0, 0, 0.1]}})
        http.post("/v1/sim/step", json={"ticks": 40}).raise_for_status()
        assert http.delete("/v1/recordings/current").status_code == 200
    path = data / "recordings" / "rand.mcap"
    with open(path, "rb") as f:
        commands = [
            json.loads(m.data)
            for _, _, m in make_reader(f).iter_messages(topics=["/armfleet/commands"])
        ]
    rand = next(c for c in commands if c["kind"] == "randomize")
    assert rand["seed"] == 11 and rand["spec"] == SPEC
    assert {c["kind"] for c in commands} >= {"set_entity", "set_params"}
    # Replayed in this process (`armfleet replay` runs this same function; the command itself
    # is tested in test_recording.py and test_your_cell.py): a MuJoCo Warp process less to start.
    report = replay(path)
    assert report.divergence is None, report.divergence
    assert report.tolerance is None  # compared bit for bit
    assert report.states_compared > 0 and report.commands >= 3 and report.truncated is None
