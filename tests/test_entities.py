"""Entities (the scene's named free bodies) per world: read, write at one tick boundary, refuse.

A real server over real sockets (HTTP and the WebSocket op protocol), paused so that ticks are
counted exactly; and the engines themselves, to show a written pose is held bit for bit.
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import httpx
import numpy as np
import pytest
from conftest import replies_of
from websockets.sync.client import connect

from service.core.commands.entities import SetEntities
from service.core.sim.batch import TickWrites
from service.core.sim.entities import entity_table
from service.core.sim.robot import load_robot

ROBOT = load_robot()
TABLE = entity_table(ROBOT.mjm)
HOME_CUBE = ROBOT.mjm.key_qpos[ROBOT.home_key][TABLE.qpos[0] : TABLE.qpos[0] + 7]
DT = 1 / 60


def test_the_default_scene_has_one_entity_and_bounds():
    assert TABLE.names == ("cube",)
    assert (TABLE.lower < HOME_CUBE[:3]).all() and (HOME_CUBE[:3] < TABLE.upper).all()


def test_a_pose_set_at_tick_t_is_read_at_t_in_that_world_only(paused):
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        before = http.get("/v1/worlds/0/entities").json()
        assert [e["name"] for e in before["entities"]] == ["cube"]
        assert before["entities"][0]["position"] == pytest.approx(HOME_CUBE[:3].tolist(), abs=1e-3)

        # in the air, turned 90° about z; a near-unit quaternion is normalised and said so
        s = math.sqrt(0.5)
        body = {"position": [0.3, -0.5, 1.2], "orientation": [0.7071, 0, 0, 0.7071]}
        body |= {"linear": [0, 0, 0], "angular": [0, 0, 0]}
        ack = http.put("/v1/worlds/2/entities/cube", json=body).json()
        assert ack["worlds"] == [2] and ack["normalised"] == ["orientation (norm 0.99999)"]
        stepped = http.post("/v1/sim/step", json={"ticks": 1}).json()
        assert stepped["tick"] == ack["tick"]
        cube = http.get("/v1/worlds/2/entities/cube").json()
        assert cube["tick"] == ack["tick"]
        # one tick of free fall from rest: x, y and the orientation as written, z a little lower
        assert cube["position"][:2] == pytest.approx([0.3, -0.5], abs=1e-12)
        assert 1.2 - 9.81 * DT**2 < cube["position"][2] < 1.2 - 9.81 * DT**2 / 2
        assert cube["orientation"] == pytest.approx([s, 0, 0, s], abs=1e-12)
        assert cube["linear"][:2] == [0, 0] and cube["linear"][2] == pytest.approx(-9.81 * DT)
        other = http.get("/v1/worlds/1/entities/cube").json()
        assert other["position"][2] == pytest.approx(HOME_CUBE[2], abs=1e-3)

        # many worlds at one tick boundary, a twist too
        writes = [
            {
                "world": w,
                "name": "cube",
                "position": [0.3 - 0.1 * w, -0.5, 1.5],
                "linear": [1, 0, 0],
            }
            for w in range(4)
        ]
        ack = http.post("/v1/entities", json={"writes": writes}).json()
        assert ack["worlds"] == [0, 1, 2, 3] and ack["normalised"] == []
        http.post("/v1/sim/step", json={"ticks": 1})
        for w in range(4):
            cube = http.get(f"/v1/worlds/{w}/entities/cube").json()
            assert cube["tick"] == ack["tick"]
            assert cube["position"][0] == pytest.approx(0.3 - 0.1 * w + DT, abs=1e-9)


@pytest.mark.parametrize(
    ("body", "field", "words"),
    [
        ({"position": [0.6, 0.1, 9.0]}, "position", "outside the scene's bounds at z"),
        ({"orientation": [2, 0, 0, 0]}, "orientation", "norm 2 is too far from 1"),
        ({"linear": [100, 0, 0]}, "linear", "exceeds 50 m/s"),
        ({}, "position", "nothing to write"),
    ],
)
def test_bad_values_are_refused_with_the_field_and_the_limit(paused, body, field, words):
    reply = httpx.put(f"{paused.url}/v1/worlds/0/entities/cube", json=body, timeout=10)
    assert reply.status_code == 422, reply.text
    assert field in reply.text and words in reply.text


def test_an_unknown_entity_or_one_bad_write_of_many_changes_nothing(paused):
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        # an unknown entity in the path is a resource that is not there: 404 (issue 38, item 4)
        reply = http.put("/v1/worlds/0/entities/sphere", json={"position": [0.6, 0.1, 1]})
        assert reply.status_code == 404 and "no entity 'sphere'" in reply.text
        assert "cube" in reply.text  # it names the entities there are
        reply = http.get("/v1/worlds/1/entities/no_such_part")
        assert reply.status_code == 404 and "no entity 'no_such_part'" in reply.json()["detail"]
        # in a body, an unknown name is a bad field of the request: 422
        reply = http.post("/v1/entities", json={"writes": [{"world": 0, "name": "sphere"}]})
        assert reply.status_code == 422 and "unknown entity 'sphere'" in reply.text
        before = http.get("/v1/worlds/3/entities/cube").json()
        writes = [
            {"world": 3, "name": "cube", "position": [0.6, 0.1, 1.0]},
            {"world": 1, "name": "cube", "position": [0.6, 0.1, -5.0]},
        ]
        reply = http.post("/v1/entities", json={"writes": writes})
        assert reply.status_code == 422 and '"writes","1","position"' in reply.text
        http.post("/v1/sim/step", json={"ticks": 1})
        after = http.get("/v1/worlds/3/entities/cube").json()
        # world 3 went on from where it was (flying at 1 m/s), not from the refused write's pose
        assert after["position"][0] == pytest.approx(before["position"][0] + DT, abs=1e-6)
        assert after["position"][0] != pytest.approx(0.6, abs=0.1)


def test_the_websocket_op_sets_an_entity_and_refuses_non_finite_values(paused):
    with connect(f"{paused.ws_url}/v1/ws") as ws:
        ws.send(
            json.dumps(
                {
                    "op": "set_entity",
                    "id": 1,
                    "world": 1,
                    "name": "cube",
                    "position": [0.7, 0.0, 1.0],
                }
            )
        )
        ws.send('{"op": "set_entity", "id": 2, "world": 1, "name": "cube", "linear": [NaN, 0, 0]}')
        replies = replies_of(ws, 2)
    assert replies[0]["op"] == "ack" and replies[0]["world"] == 1 and replies[0]["tick"] > 0
    assert replies[1]["op"] == "error" and "linear" in replies[1]["detail"]
    assert "not finite" in replies[1]["detail"]


def _batch(engine: str, nworld: int):
    if engine == "mujoco":
        from service.engines.native import NativeBatch

        return NativeBatch(nworld)
    from service.engines.warp import WorldBatch

    return WorldBatch(nworld, capture=False)


@pytest.mark.parametrize("engine", ["mujoco", "warp"])
def test_every_engine_holds_a_written_pose_bit_for_bit(engine):
    batch = _batch(engine, 3)
    try:
        pose = np.array([0.55, 0.05, 1.1, 0.5, 0.5, 0.5, 0.5])
        item = {"world": 1, "name": "cube", "position": pose[:3].tolist()}
        item["orientation"] = pose[3:].tolist()
        cmd = SetEntities.create(
            SimpleNamespace(loop=SimpleNamespace(batch=batch), nworld=3), [item]
        )
        batch.write(TickWrites(state=cmd.writes))
        got = batch.qpos()[1, TABLE.qpos[0] : TABLE.qpos[0] + 7]
        assert np.array_equal(got, pose.astype(got.dtype))
        assert np.array_equal(batch.qpos()[0], batch.qpos()[2])  # the others untouched
        assert not np.array_equal(batch.qpos()[0], batch.qpos()[1])
    finally:
        batch.close()


def test_the_python_clients_set_and_read_entities_and_parameters(paused):
    import asyncio

    from clients import ArmfleetClient, AsyncArmfleetClient

    with ArmfleetClient(paused.url) as client:
        ack = client.set_entity(0, "cube", position=[0.3, -0.5, 1.0], linear=[0, 0, 0])
        client.set_params(0, {"cube.mass": 0.2})
        client.step(1)
        cube = client.entity(0, "cube")
        assert cube["tick"] == ack["tick"] and cube["position"][:2] == [0.3, -0.5]
        assert client.params(0)["params"]["cube.mass"] == 0.2
        assert any(p["name"] == "payload" for p in client.param_table()["params"])
        many = client.set_entities(
            [{"world": w, "name": "cube", "angular": [0, 0, 1]} for w in (1, 2)]
        )
        assert many["worlds"] == [1, 2]

    async def go() -> None:
        async with AsyncArmfleetClient(paused.url) as client:
            ack = await client.set_params_many(
                [(1, {"cube.friction": 0.5}), (2, {"payload": [1, 0, 0, 0]})]
            )
            await client.step(1)
            assert (await client.params(1))["params"]["cube.friction"] == 0.5
            assert (await client.params(2))["tick"] == ack["tick"]
            assert [e["name"] for e in (await client.entities(2))["entities"]] == ["cube"]

    asyncio.run(go())
