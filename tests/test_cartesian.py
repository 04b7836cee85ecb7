"""Cartesian commands end to end on real servers over real sockets: the TCP pose a world
reports equals MuJoCo's flange pose, IK round-trips, set_tcp, TCP targets, jogs in base and
tool frames and moveL through REST, the WebSocket ops and the Python clients (sync and async);
a pose no configuration reaches is a 422 naming the field, and other worlds never notice."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from typing import Any

import httpx
import numpy as np
import pytest
from conftest import wait_for
from jog_checks import rotvec_matrix
from websockets.sync.client import connect

from clients import ArmfleetClient, AsyncArmfleetClient
from clients.errors import ArmfleetError, Conflict
from clients.testing import serve


def _rot(q: np.ndarray) -> np.ndarray:
    """A rotation matrix from a quaternion w x y z (the test's own, not the service's)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _in_world(tcp: dict, pose: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """A base-frame pose in MuJoCo's world frame (the reply's base_in_world)."""
    base = tcp["base_in_world"]
    rb, pb = _rot(base["quaternion"]), np.array(base["position"])
    return rb @ np.array(pose[:3]) + pb, rb @ rotvec_matrix(pose[3:])


def test_the_tcp_pose_is_mujocos_flange_and_ik_round_trips(paused) -> None:
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        http.put("/v1/worlds/1/targets", json={"position": [0.3, -1.2, 1.4, -1.6, -1.2, 0.4, 0]})
        http.post("/v1/sim/step", json={"ticks": 30})
        state = http.get("/v1/worlds/1/state").json()
        tcp = http.get("/v1/worlds/1/tcp").json()
        assert tcp["tick"] == state["tick"] and tcp["tcp"] == tcp["flange"]  # no offset yet
        assert tcp["safety_mode"] == state["safety_mode"] == "NORMAL"
        pos, rot = _in_world(tcp, tcp["flange"])
        assert np.abs(pos - state["flange"]["position"]).max() < 1e-6
        assert np.abs(rot - _rot(state["flange"]["quaternion"])).max() < 1e-6
        # the actual q (as the state's JSON rounds it) through POST fk gives the same pose;
        # IK of it gives q back
        q = state["position"][:6]
        assert http.post("/v1/worlds/1/fk", json={"q": q}).json()["pose"] == pytest.approx(
            tcp["flange"], abs=1e-6
        )
        ik = http.post("/v1/worlds/1/ik", json={"pose": tcp["flange"], "q_near": q}).json()
        assert ik["ok"] and np.abs(np.array(ik["q"]) - q).max() < 1e-6
        far = http.post("/v1/worlds/1/ik", json={"pose": [2.5, 0, 0, 0, 0, 0]}).json()
        assert far == {"world": 1, "ok": False, "q": None, "reason": "out_of_reach", "singular": []}


def test_set_tcp_targets_and_jogs_over_rest_and_websocket(paused) -> None:
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        other = http.get("/v1/worlds/3/tcp").json()
        ack = http.put("/v1/worlds/2/tcp_offset", json={"tcp": [0, 0, 0.2, 0, 0, 0]})
        assert ack.status_code == 200 and ack.json()["tcp"] == [0, 0, 0.2, 0, 0, 0]
        bad = http.put("/v1/worlds/2/tcp_offset", json={"tcp": [0, 0, 2.0, 0, 0, 0]})
        assert bad.status_code == 422 and "tcp[2]" in bad.text and "1" in bad.text, bad.text
        start = http.get("/v1/worlds/2/tcp").json()
        flange, tcp = np.array(start["flange"]), np.array(start["tcp"])
        z_tool = rotvec_matrix(flange[3:]) @ [0, 0, 0.2]
        assert tcp[:3] == pytest.approx(flange[:3] + z_tool, abs=1e-9)
        goal = (np.array(start["target_tcp"]) + [0.05, -0.1, -0.05, 0, 0, 0]).tolist()
        moved = http.put("/v1/worlds/2/tcp_target", json={"pose": goal})
        assert moved.status_code == 200, moved.text
        assert http.get("/v1/worlds/2/tcp").json()["target_tcp"] == pytest.approx(goal, abs=1e-7)
        for body, field in (
            ({"pose": [2.9, 0, 0, 0, 0, 0]}, "pose"),  # out of reach
            ({"pose": [0, 0, 0.5, 0, 0]}, "pose"),
            ({"pose": [0, 0, 9, 0, 0, 0]}, "pose"),  # beyond the schema's ±3 m
        ):
            bad = http.put("/v1/worlds/2/tcp_target", json=body)
            assert bad.status_code == 422 and field in bad.text, bad.text
        before = http.get("/v1/worlds/2/tcp").json()["target_tcp"]
        jog = http.post("/v1/worlds/2/jog", json={"axis": "z", "step": 0.02, "frame": "base"})
        assert jog.status_code == 200, jog.text
        after = http.get("/v1/worlds/2/tcp").json()["target_tcp"]
        assert np.array(after) - before == pytest.approx([0, 0, 0.02, 0, 0, 0], abs=1e-7)
        bad = http.post("/v1/worlds/2/jog", json={"axis": "q", "step": 0.02})
        assert bad.status_code == 422 and "axis" in bad.text
        bad = http.post("/v1/worlds/2/jog", json={"axis": "x", "step": 0.5})
        assert bad.status_code == 422 and "step" in bad.text
    with connect(f"{paused.ws_url}/v1/ws/worlds/2") as ws:
        msgs = [
            {"op": "jog", "id": 1, "axis": "rz", "step": 0.1, "frame": "tool"},
            {"op": "tcp_target", "id": 2, "pose": [2.9, 0, 0, 0, 0, 0]},
            {"op": "set_tcp", "id": 3, "tcp": [0, 0, 0.1, 0, 0, 0]},
        ]
        for m in msgs:
            ws.send(json.dumps(m))
        replies = {}
        while len(replies) < 3:
            msg = json.loads(ws.recv(timeout=5))
            if msg["op"] in ("ack", "error"):
                replies[msg["id"]] = msg
    assert replies[1]["op"] == "ack" and len(replies[1]["target"]) == 7
    assert replies[2]["op"] == "error" and "out_of_reach" in replies[2]["detail"]
    assert replies[3]["op"] == "ack" and replies[3]["tcp"] == [0, 0, 0.1, 0, 0, 0]
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        turned = http.get("/v1/worlds/2/tcp").json()
        # a tool-frame rz step turns the TCP about its own z: the position stays
        tcp_now = np.array(turned["target_tcp"])
        assert tcp_now[:3] - [0, 0, 0] == pytest.approx(
            np.array(after[:3]) - rotvec_matrix(after[3:]) @ [0, 0, 0.1], abs=1e-6
        )
        assert http.get("/v1/worlds/3/tcp").json() == other  # the other world never noticed


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    u = b - a
    t = np.clip((p - a) @ u / (u @ u), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * u), axis=1)


@pytest.fixture(scope="module")
def realtime(tmp_path_factory: pytest.TempPathFactory):
    log = tmp_path_factory.mktemp("cartesian")
    with serve(worlds=2, mode="realtime", extra_args=("--engine", "mujoco"), log_dir=log) as srv:
        yield srv


def test_move_linear_keeps_the_tcp_within_a_millimetre_of_the_line(realtime) -> None:
    """moveL through the sync client; every state streamed over the WebSocket while it runs:
    MuJoCo's own flange pose, plus the TCP offset, measured against the straight segment."""
    arm = ArmfleetClient(realtime.url, timeout=20)
    offset = [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]
    arm.set_tcp(0, offset)
    start = arm.tcp(0)
    goal = (np.array(start["target_tcp"]) + [0.15, -0.25, -0.1, 0, 0, 0]).tolist()
    states, stop = [], threading.Event()

    def record() -> None:
        for s in arm.stream(0):
            states.append(s)
            if stop.is_set():
                return

    reader = threading.Thread(target=record, daemon=True)
    reader.start()
    while not states:
        time.sleep(0.05)
    started = arm.move_linear(0, goal, speed=0.25, accel=1.2)  # UR's default acceleration
    done = arm.trajectory(0, wait=30)
    time.sleep(0.3)
    stop.set()
    reader.join(5)
    assert done.state == "succeeded", done
    a, _ = _in_world(start, start["target_tcp"])
    b, _ = _in_world(start, goal)
    during = [s for s in states if started.start_tick <= s.tick <= started.end_tick + 30]
    assert len(during) > 0.8 * (started.end_tick - started.start_tick)
    tcp = np.array([s.flange_position + _rot(s.flange_quaternion) @ offset[:3] for s in during])
    deviation = _segment_distance(tcp, a, b)
    print(f"moveL 0.25 m/s 1.2 m/s²: max {1000 * deviation.max():.3f} mm from the line")
    assert deviation.max() < 1e-3
    assert np.linalg.norm(tcp[-1] - b) < 1e-3
    assert np.linalg.norm(tcp[len(tcp) // 2] - a) > 0.05  # it did travel
    with pytest.raises(ArmfleetError) as fast:
        arm.move_linear(0, start["target_tcp"], speed=3.0, accel=150)
    assert fast.value.status == 422 and "speed" in str(fast.value)


def test_the_async_client_and_the_websocket_op_start_a_line(realtime) -> None:
    async def go() -> tuple[dict, dict]:
        async with AsyncArmfleetClient(realtime.url, timeout=20) as arm:
            now = await arm.tcp(1)
            ack = await arm.jog(1, "x", 0.01, frame="tool")
            assert len(ack.target) == 7
            ik = await arm.ik(1, now["target_tcp"])
            return now, ik

    now, ik = asyncio.run(go())
    assert ik["ok"]
    goal = (np.array(now["target_tcp"]) + [0, 0, -0.05, 0, 0, 0]).tolist()
    with connect(f"{realtime.ws_url}/v1/ws/worlds/1") as ws:
        ws.send(json.dumps({"op": "move_linear", "id": 9, "pose": goal, "speed": 0.1}))
        while (msg := json.loads(ws.recv(timeout=5)))["op"] not in ("ack", "error"):
            pass
    assert msg["op"] == "ack" and msg["trajectory"]["world"] == 1, msg
    arm = ArmfleetClient(realtime.url, timeout=20)
    status = arm.wait_trajectory(msg["trajectory"]["id"], timeout=30)
    assert status.succeeded
    time.sleep(1.0)  # the servos settle on the goal
    assert arm.tcp(1)["tcp"][:3] == pytest.approx(goal[:3], abs=1e-3)


HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
INTO_TABLE = [0.0, -1.17, 1.57, -1.57, -1.57, 0.0]  # home, shoulder 0.4 rad down: pads 8 cm in
INTO_FLOOR = [3.14, 0.2, 1.57, -1.57, -1.57, 0.0]  # turned away from the table, wrist 20 cm in


def _stepped_mode(http: httpx.Client, world: int) -> str:
    """The world's safety mode after one tick of the paused server (the watch runs per tick)."""
    assert http.post("/v1/sim/step", json={"ticks": 1}).status_code == 200
    state = http.get(f"/v1/worlds/{world}/state").json()
    assert http.get(f"/v1/worlds/{world}/tcp").json()["safety_mode"] == state["safety_mode"]
    return state["safety_mode"]


def test_a_target_into_any_fixed_obstacle_is_a_protective_stop_on_a_world_without_ur_ports(
    paused,
) -> None:
    """A REST target through the table (world 3) or the floor (world 0) of a server with no
    UR ports: the world is protective-stopped before the next tick takes the target, its
    state, /tcp and WebSocket frame say so, every command that moves it is refused (409),
    unlocking is refused within 5 s (REST and the WebSocket op) and done after, a reset
    clears it at once; the arm may then be driven back out; world 1 never notices."""
    arm = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"] + [
        f"wrist_{i}_joint" for i in (1, 2, 3)
    ]
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        other = http.get("/v1/worlds/1/state").json()["target"]
        for world, q in ((3, INTO_TABLE), (0, INTO_FLOOR)):
            held = http.get(f"/v1/worlds/{world}/state").json()["position"][:6]
            put = http.put(f"/v1/worlds/{world}/targets", json={"name": arm, "position": q})
            assert put.status_code == 200, put.text  # accepted: the watch judges it at the tick
            assert _stepped_mode(http, world) == "PROTECTIVE_STOP"
            if world == 3:  # at once: the 5 s count from the stop (REST, then the WebSocket)
                early = http.post("/v1/worlds/3/unlock_protective_stop")
                assert early.status_code == 409 and "5 s" in early.json()["detail"], early.text
            else:
                with connect(f"{paused.ws_url}/v1/ws/worlds/0") as ws:
                    ws.send(json.dumps({"op": "unlock_protective_stop", "id": 1}))
                    while (msg := json.loads(ws.recv(timeout=5)))["op"] not in ("ack", "error"):
                        if msg["op"] == "state":
                            assert msg["safety_mode"] == "PROTECTIVE_STOP"
                    assert msg["op"] == "error" and "5 s" in msg["detail"], msg
            state = http.get(f"/v1/worlds/{world}/state").json()
            # held where the arm was after one tick of motion, far from the target
            assert np.abs(np.array(state["target"][:6]) - held).max() < 0.05
            again = http.post(f"/v1/worlds/{world}/jog", json={"axis": "z", "step": 0.01})
            assert again.status_code == 409 and "protective" in again.json()["detail"]
        assert http.get("/v1/worlds/1/state").json()["safety_mode"] == "NORMAL"
        log = paused.log()
        assert "into table_top" in log and "into floor" in log, log[-2000:]
        assert http.post("/v1/worlds/0/reset").status_code == 200  # at once
        assert _stepped_mode(http, 0) == "NORMAL"

        def unlocked() -> bool:
            if http.post("/v1/worlds/3/unlock_protective_stop").status_code == 200:
                return True
            time.sleep(0.2)
            return False

        wait_for(unlocked, "the unlock 5 s after the stop", timeout=20)
        assert _stepped_mode(http, 3) == "NORMAL"
        back = http.put("/v1/worlds/3/targets", json={"name": arm, "position": HOME})
        assert back.status_code == 200, back.text  # out of the table: allowed
        assert _stepped_mode(http, 3) == "NORMAL"
        assert http.get("/v1/worlds/1/state").json()["target"] == other  # never noticed
        assert http.post("/v1/worlds/3/reset").status_code == 200


def _stepped_until(http: httpx.Client, world: int, mode: str, bursts: int = 60) -> int:
    """Step the paused server 10 ticks at a time until `world`'s mode is `mode`; the ticks it
    took (None after `bursts` bursts)."""
    for i in range(bursts):
        assert http.post("/v1/sim/step", json={"ticks": 10}).status_code == 200
        if http.get(f"/v1/worlds/{world}/state").json()["safety_mode"] == mode:
            return 10 * (i + 1)
    raise AssertionError(f"world {world} not {mode} after {10 * bursts} ticks")


def test_a_joint_held_at_its_torque_limit_is_a_protective_stop_a_hard_acceleration_is_not(
    paused,
) -> None:
    """The torque watch of every world (no UR ports here): world 2 folded onto itself (the
    elbow driven to 3.1 rad with the shoulder raised; clear of every fixed obstacle, so the
    clearance watch lets it through) presses wrist_1 at its torque limit without moving:
    protective-stopped, said in the log, held, commands refused. World 1's shoulder stepped
    by 2 rad saturates its servo for about 0.3 s while it accelerates, and stays NORMAL."""
    arm = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"] + [
        f"wrist_{i}_joint" for i in (1, 2, 3)
    ]
    folded = [0.0, -0.8, 3.1, -1.57, -1.57, 0.0]
    swung = [2.0, *HOME[1:]]
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        assert http.post("/v1/reset", json={"worlds": [1, 2]}).status_code == 200
        for world, q in ((1, swung), (2, folded)):
            put = http.put(f"/v1/worlds/{world}/targets", json={"name": arm, "position": q})
            assert put.status_code == 200, put.text
        _stepped_until(http, 2, "PROTECTIVE_STOP")
        assert "wrist_1_joint held at its torque limit" in paused.log()
        swung_state = http.get("/v1/worlds/1/state").json()
        assert swung_state["safety_mode"] == "NORMAL"
        state = http.get("/v1/worlds/2/state").json()
        # held where it was stopped: the elbow far short of its 3.1 rad target
        assert np.abs(np.array(state["target"][:6]) - state["position"][:6]).max() < 0.05
        bad = http.put("/v1/worlds/2/targets", json={"name": arm, "position": HOME})
        assert bad.status_code == 409 and "torque limit" in bad.json()["detail"], bad.text
        for _ in range(6):  # the swing is over by now, and it never stopped
            assert http.post("/v1/sim/step", json={"ticks": 10}).status_code == 200
        swung_state = http.get("/v1/worlds/1/state").json()
        assert swung_state["safety_mode"] == "NORMAL"
        assert swung_state["position"][0] == pytest.approx(2.0, abs=0.02)
        assert http.post("/v1/reset", json={"worlds": [1, 2]}).status_code == 200


def test_a_protective_stop_is_triggered_over_rest_and_the_websocket(paused) -> None:
    """ur_rtde's triggerProtectiveStop on any world: REST (world 1) and the WebSocket op
    (world 3) stop the world where it is, a second trigger keeps the first cause, a bad body
    is refused naming the field, commands are refused until a reset; world 0 never notices."""
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        other = http.get("/v1/worlds/0/state").json()
        stop = http.post("/v1/worlds/1/trigger_protective_stop")
        assert stop.status_code == 200, stop.text
        reply = stop.json()
        assert reply["safety_mode"] == "PROTECTIVE_STOP" and "REST" in reply["why"]
        assert _stepped_mode(http, 1) == "PROTECTIVE_STOP"
        jog = http.post("/v1/worlds/1/jog", json={"axis": "z", "step": 0.01})
        assert jog.status_code == 409 and "triggered by the user" in jog.json()["detail"]
        with connect(f"{paused.ws_url}/v1/ws/worlds/3") as ws:
            ws.send(json.dumps({"op": "trigger_protective_stop", "id": 1, "why": "x"}))
            while (msg := json.loads(ws.recv(timeout=10)))["op"] not in ("ack", "error"):
                pass
            assert msg["op"] == "error" and msg["detail"].startswith("why:"), msg
            assert _stepped_mode(http, 3) == "NORMAL"  # refused: nothing changed
            for msg_id in (2, 3):  # the second keeps the first's cause
                ws.send(json.dumps({"op": "trigger_protective_stop", "id": msg_id}))
                while (msg := json.loads(ws.recv(timeout=10)))["op"] not in ("ack", "error"):
                    pass
                assert msg["op"] == "ack" and msg["id"] == msg_id, msg
                assert msg["safety_mode"] == "PROTECTIVE_STOP" and "WebSocket" in msg["why"]
        assert _stepped_mode(http, 3) == "PROTECTIVE_STOP"
        again = http.post("/v1/worlds/3/trigger_protective_stop").json()
        assert "WebSocket" in again["why"]  # the first cause is kept
        assert http.post("/v1/worlds/9/trigger_protective_stop").status_code in (404, 422)
        assert http.post("/v1/reset", json={"worlds": [1, 3]}).status_code == 200
        assert _stepped_mode(http, 1) == "NORMAL" and _stepped_mode(http, 3) == "NORMAL"
        now = http.get("/v1/worlds/0/state").json()
        assert now["safety_mode"] == "NORMAL" and now["target"] == other["target"]


def test_the_python_clients_trigger_and_unlock_a_protective_stop(paused) -> None:
    """The sync client (world 2) and the async one (world 3): a trigger stops the world (the
    state says so, a move is refused), an unlock within 5 s is refused with the robot's rule,
    one after it brings the world back to NORMAL and moves are taken again; world 0 never
    notices. The 5 s are waited once, for both clients at once."""

    async def trigger_and_early_unlock() -> tuple[Any, Any]:
        async with AsyncArmfleetClient(paused.url, timeout=20) as arm:
            stop = await arm.trigger_protective_stop(3)
            try:
                early = await arm.unlock_protective_stop(3)
            except Conflict as refused:
                early = refused
            return stop, early

    def early_unlock(arm: ArmfleetClient, world: int) -> Any:
        try:
            return arm.unlock_protective_stop(world)
        except Conflict as refused:
            return refused

    with ArmfleetClient(paused.url, timeout=20) as arm:
        other = arm.state(0)
        asked = time.monotonic()  # before the stops: an unlock before asked + 5 s is refused
        stops = {2: arm.trigger_protective_stop(2)}
        early = {2: early_unlock(arm, 2)}
        stops[3], early[3] = asyncio.run(trigger_and_early_unlock())
        stopped = time.monotonic()  # after both replies: both stops are older than this
        for world, stop in stops.items():
            assert (stop.world, stop.safety_mode) == (world, "PROTECTIVE_STOP")
            assert "triggered by the user (REST)" in stop.why
            if isinstance(early[world], Conflict):  # within 5 s: the robot's rule, in words
                assert early[world].status == 409
                assert "may be unlocked 5 s after it at the earliest" in early[world].detail
            else:  # only a box so loaded that 5 s passed between two requests gets here
                assert time.monotonic() - asked >= 5.0, early[world]
            assert arm.state(world).safety_mode == "PROTECTIVE_STOP"
            with pytest.raises(Conflict):
                arm.increment(world, "elbow_joint", 0.05)
        time.sleep(max(0.0, stopped + 5.0 - time.monotonic()))
        unlocked = arm.unlock_protective_stop(2)
        assert (unlocked.world, unlocked.safety_mode, unlocked.why) == (2, "NORMAL", None)

        async def late_unlock() -> Any:
            async with AsyncArmfleetClient(paused.url, timeout=20) as arm:
                return await arm.unlock_protective_stop(3)

        assert asyncio.run(late_unlock()).safety_mode == "NORMAL"
        for world in (2, 3):
            assert arm.state(world).safety_mode == "NORMAL"
            assert arm.increment(world, "elbow_joint", 0.05).world == world
        now = arm.state(0)
        assert now.safety_mode == "NORMAL" and now.target == pytest.approx(other.target)
        arm.reset([2, 3])
