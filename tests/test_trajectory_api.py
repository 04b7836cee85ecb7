"""Trajectories end to end: a real `armfleet serve` (MuJoCo Warp on the CPU), the real Python
clients and a raw WebSocket; recorded to MCAP and replayed bit-exactly by `service.replay`.

The server runs paused: each test steps it (or switches to fast mode and lets the client wait
for the outcome), so outcomes are the same however loaded the machine is.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from conftest import HOME, JOINTS, Server, serve
from websockets.sync.client import connect

from clients import (
    ArmfleetClient,
    AsyncArmfleetClient,
    Conflict,
    InvalidRequest,
    NotFound,
    point,
    tolerance,
)
from service.persistence.replay import read_recording, replay_recording

NWORLD = 4
ARM = JOINTS[:6]
GOAL = (np.array(HOME[:6]) + [0.3, -0.2, 0.2, 0.2, -0.3, 0.4]).tolist()
MID = (np.array(HOME[:6]) + [0.15, -0.1, 0.1, 0.1, -0.15, 0.2]).tolist()
POINTS = [point(MID, 0.5), point(GOAL, 1.0)]


@pytest.fixture(scope="module")
def paused(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, Path]]:
    tmp = tmp_path_factory.mktemp("trajectory")
    data = tmp / "data"
    with serve(NWORLD, "paused", extra_args=("--data-dir", str(data)), log_dir=tmp) as srv:
        yield srv, data


@pytest.fixture
def arm(paused) -> Iterator[ArmfleetClient]:
    srv, _ = paused
    with ArmfleetClient(srv.url, timeout=60) as client:
        client.set_mode("paused")
        client.reset()
        client.step(1)
        yield client


def test_post_get_delete_and_the_outcome(arm):
    started = arm.start_trajectory(1, ARM, POINTS)
    assert started.world == 1 and started.end_tick - started.start_tick + 1 == 60
    arm.step(30)
    status = arm.trajectory(1)
    assert status.state == "running" and 0.4 < status.progress < 0.6
    assert status.joint_names == tuple(ARM) and status.error.shape == (6,)
    assert np.abs(status.error).max() < 0.05
    arm.step(31)
    done = arm.trajectory(1)
    assert done.succeeded and done.finished_tick == started.end_tick and done.progress == 1.0
    np.testing.assert_array_equal(arm.state(1).target[:6], GOAL)
    with pytest.raises(Conflict, match="runs no trajectory"):
        arm.cancel_trajectory(1)
    with pytest.raises(NotFound, match="has not run a trajectory"):
        arm.trajectory(3)


def test_a_trajectory_is_read_by_id_after_a_newer_one_replaced_it(arm, paused):
    srv, _ = paused
    first = arm.start_trajectory(2, ARM, POINTS)
    arm.step(10)
    second = arm.start_trajectory(2, ARM, [point(MID, 0.5)])
    arm.step(1)
    assert arm.trajectory(2).id == second.id  # the world's own route shows the newer one
    old = httpx.get(f"{srv.url}/v1/trajectories/{first.id}", timeout=10)
    assert old.status_code == 200, old.text
    assert old.json()["id"] == first.id and old.json()["state"] == "aborted"
    assert old.json()["reason"] == "preempted"
    missing = httpx.get(f"{srv.url}/v1/trajectories/999999", timeout=10)
    assert missing.status_code == 404 and "999999" in missing.json()["detail"]


def test_cancel_holds_and_a_button_press_takes_over(arm):
    arm.start_trajectory(0, ARM, POINTS)
    arm.start_trajectory(2, ARM, POINTS)
    arm.step(20)
    cancelled = arm.cancel_trajectory(0)
    assert cancelled.state == "aborted" and cancelled.reason == "cancelled"
    held = arm.state(0).target
    press = arm.increment(2, "elbow_joint", 0.1)
    arm.step(10)
    np.testing.assert_array_equal(arm.state(0).target, held)  # holds where it was
    np.testing.assert_array_equal(arm.state(2).target, press.target)
    assert arm.trajectory(2).reason == "manual_override"


def test_a_gripper_command_during_an_arm_trajectory_moves_the_finger_only(arm):
    started = arm.start_trajectory(1, ARM, POINTS)
    arm.step(10)
    arm.set_targets(1, {"finger_joint": 0.4})  # the gripper: not one of the trajectory's joints
    arm.step(started.end_tick - arm.state(1).tick)
    done = arm.trajectory(1)
    assert done.succeeded and done.finished_tick == started.end_tick
    state = arm.state(1)
    np.testing.assert_array_equal(state.target, [*GOAL, 0.4])
    assert state.position[6] > 0.2  # the finger closed meanwhile
    arm.start_trajectory(1, ARM, POINTS)
    arm.step(5)
    arm.set_targets(1, {"wrist_2_joint": -1.0})  # one of its joints: takes over
    assert arm.trajectory(1).reason == "manual_override"


@pytest.mark.parametrize(
    ("points", "field", "limit"),
    [
        ([point(MID, 1.0), point(GOAL, 1.0)], "points[1].time_from_start", "increase"),
        ([point([9.0, *MID[1:]], 1.0)], "points[0].positions[0]", "limits"),
        ([point(MID, 3601.0)], "points.0.time_from_start", "3600"),
        ([point(MID, 0.01 * (i + 1)) for i in range(1001)], "points", "1000"),
    ],
)
def test_bad_trajectories_are_422_naming_field_and_limit_and_change_nothing(
    arm, points, field, limit
):
    before = arm.state(1).target
    with pytest.raises(InvalidRequest) as err:
        arm.start_trajectory(1, ARM, points)
    assert field in str(err.value) and limit in str(err.value)
    arm.step(2)
    np.testing.assert_array_equal(arm.state(1).target, before)


def test_batch_starts_every_world_at_one_tick_and_names_unknown_worlds(arm, paused):
    many = arm.start_trajectories("0-3", ARM, POINTS)
    assert many.worlds.tolist() == [0, 1, 2, 3] and len(set(many.ids.tolist())) == 4
    srv, _ = paused
    r = httpx.post(
        f"{srv.url}/v1/trajectories",
        json={"worlds": [1, 9], "trajectory": {"joint_names": ARM, "points": POINTS}},
    )
    assert r.status_code == 404 and "9" in r.json()["detail"]
    arm.step(61)
    assert all(arm.trajectory(w).id == i for w, i in zip(many.worlds, many.ids, strict=True))
    assert {arm.trajectory(w).state for w in range(NWORLD)} == {"succeeded"}


def test_clients_wait_for_the_outcome_sync_and_async(arm, paused):
    srv, _ = paused
    arm.set_mode("fast")
    try:
        tight = [tolerance("shoulder_pan_joint", position=1e-4)]
        aborted = arm.follow_trajectory(3, ARM, POINTS, timeout=60, path_tolerance=tight)
        assert aborted.reason == "path_tolerance" and "shoulder_pan_joint" in aborted.detail

        async def run() -> object:
            async with AsyncArmfleetClient(srv.url, timeout=60) as client:
                goal = [tolerance(n, position=0.01) for n in ARM]
                return await client.follow_trajectory(
                    3, ARM, POINTS, timeout=60, goal_tolerance=goal, goal_time_tolerance=1.0
                )

        done = asyncio.run(run())
        assert done.succeeded and np.abs(done.error).max() <= 0.01
    finally:
        arm.set_mode("paused")


def test_websocket_trajectory_op_is_acked_and_state_frames_carry_its_status(arm, paused):
    srv, _ = paused
    with connect(f"{srv.ws_url}/v1/ws/worlds/2") as ws:
        body = {"joint_names": ARM, "points": POINTS}
        ws.send(json.dumps({"op": "trajectory", "id": 5, **body}))
        ack = _reply(ws, 5)
        assert ack["op"] == "ack" and ack["tick"] == ack["trajectory"]["start_tick"]
        ws.send(json.dumps({"op": "trajectory", "id": 6, "joint_names": ["nope"], "points": []}))
        assert _reply(ws, 6)["op"] == "error"
        arm.step(10)
        frame = _state(ws, lambda f: f["tick"] >= ack["tick"] + 9)
        assert frame["trajectory"]["id"] == ack["trajectory"]["id"]
        assert frame["trajectory"]["state"] == "running" and frame["trajectory"]["progress"] > 0
        ws.send(json.dumps({"op": "cancel_trajectory", "id": 7}))
        assert _reply(ws, 7)["trajectory"]["reason"] == "cancelled"


def _reply(ws, msg_id: int) -> dict:
    while (frame := json.loads(ws.recv(timeout=10))).get("id") != msg_id:
        pass
    return frame


def _state(ws, pred) -> dict:
    while not ((frame := json.loads(ws.recv(timeout=10)))["op"] == "state" and pred(frame)):
        pass
    return frame


def test_trajectories_are_recorded_and_replayed_bit_exactly(arm, paused):
    srv, data = paused
    http = httpx.Client(base_url=srv.url, timeout=60)
    arm.start_trajectory(1, ARM, POINTS)  # already running when the recording starts
    arm.step(10)
    r = http.post("/v1/recordings", json={"name": "traj", "worlds": "0-3", "rate": 60})
    assert r.status_code == 201, r.text
    tight = [tolerance("elbow_joint", position=2e-3)]
    arm.start_trajectories([0], ARM, POINTS)
    arm.start_trajectory(2, ARM, POINTS, path_tolerance=tight)
    arm.step(15)
    arm.increment(0, "wrist_1_joint", -0.1)  # takes over world 0
    arm.set_targets(1, {"finger_joint": 0.3})  # world 1's trajectory goes on
    arm.start_trajectory(3, ARM, POINTS)
    arm.step(10)
    arm.cancel_trajectory(3)
    arm.step(50)
    assert http.delete("/v1/recordings/current").status_code == 200
    rec = read_recording(data / "recordings" / "traj.mcap")
    kinds = [c["kind"] for seg in rec.segments for cs in seg.commands.values() for c in cs]
    assert kinds.count("trajectory") == 3 and kinds.count("trajectory_cancel") == 1
    assert kinds.count("trajectory_resume") == 1
    named = [c.get("joints") for seg in rec.segments for cs in seg.commands.values() for c in cs]
    assert [6] in named  # the finger command names finger_joint (6) alone, and so does the replay
    report = replay_recording(rec)
    assert report.divergence is None and report.ticks == 75 and report.states_compared >= 300
