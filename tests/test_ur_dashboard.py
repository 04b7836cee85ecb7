"""The Dashboard server (29999) of each world, judged by ur-rtde 1.6.5's DashboardClient, with
RTDE (RTDEReceiveInterface) reporting what it changed, and a raw socket for the robot's own
answer to what it does not understand. Two worlds: one world's power off leaves the other
running.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator

import httpx
import pytest

from tests.conftest import Server, wait_for
from tests.ur_judge import DASHBOARD, ur_server

dashboard_client = pytest.importorskip("dashboard_client")  # the `test` extra: ur-rtde==1.6.5
rtde_receive = pytest.importorskip("rtde_receive")

POWER_OFF, IDLE, RUNNING = 3, 5, 7


@pytest.fixture(scope="module")
def ur(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, list[str]]]:
    with ur_server(2, tmp_path_factory.mktemp("ur-dashboard")) as pair:
        yield pair


def test_dashboard_calls_change_what_rtde_reports(ur) -> None:
    server, addrs = ur
    dash = dashboard_client.DashboardClient(addrs[0])
    dash.connect()
    rx = rtde_receive.RTDEReceiveInterface(addrs[0])
    other = rtde_receive.RTDEReceiveInterface(addrs[1])
    try:
        assert dash.isInRemoteControl()
        assert dash.polyscopeVersion() == "5.21.0.0"
        assert dash.robotmode() == "Robotmode: RUNNING"
        assert dash.safetymode() == "Safetymode: NORMAL"
        assert dash.safetystatus() == "Safetystatus: NORMAL"
        assert dash.getLoadedProgram() == "No program loaded"
        assert dash.programState() == "STOPPED <unnamed>"
        dash.powerOff()
        assert dash.robotmode() == "Robotmode: POWER_OFF"
        wait_for(lambda: rx.getRobotMode() == POWER_OFF, "RTDE reports power off")
        assert rx.getRobotStatus() & 1 == 0 and rx.getSpeedScaling() == 0.0
        assert other.getRobotMode() == RUNNING  # the other world's controller is its own
        dash.powerOn()
        wait_for(lambda: rx.getRobotMode() == IDLE, "RTDE reports idle")
        dash.brakeRelease()
        wait_for(lambda: rx.getRobotMode() == RUNNING, "RTDE reports running")
        with pytest.raises(RuntimeError, match="Failed to execute: play"):
            dash.play()  # nothing loaded: the robot refuses (ur_rtde raises its answer)
        assert not dash.running()
        dash.loadURP("pick.urp")
        assert dash.getLoadedProgram() == "Loaded program: /programs/pick.urp"
        dash.play()
        assert dash.running() and dash.programState() == "PLAYING pick.urp"
        wait_for(lambda: rx.getRuntimeState() == 2 and rx.getRobotStatus() & 2, "playing")
        dash.pause()
        assert dash.programState() == "PAUSED pick.urp"
        dash.stop()
        assert dash.programState() == "STOPPED pick.urp" and not dash.running()
        dash.unlockProtectiveStop()  # not stopped: nothing to unlock, the mode stays
        dash.closeSafetyPopup()
        assert dash.safetymode() == "Safetymode: NORMAL"
        status = httpx.get(f"{server.url}/v1/ur").json()
        assert [w["address"] for w in status["worlds"]] == addrs
        assert status["worlds"][0]["program_state"] == "STOPPED"
        assert status["ports"]["rtde"] == 30004 and status["ports"]["dashboard"] == 29999
    finally:
        dash.disconnect()
        rx.disconnect()
        other.disconnect()


def _lines(sock: socket.socket, count: int) -> list[str]:
    data = b""
    while data.count(b"\n") < count:
        chunk = sock.recv(4096)
        if not chunk:
            break
        data += chunk
    return data.decode().splitlines()


def test_an_unknown_command_gets_the_robots_answer_and_quit_closes(ur) -> None:
    _, addrs = ur
    with socket.create_connection((addrs[1], DASHBOARD), timeout=5) as sock:
        assert _lines(sock, 1) == ["Connected: Universal Robots Dashboard Server"]
        sock.sendall(b"make coffee\nload notes.txt\nPolyscopeVersion\r\nquit\n")
        assert _lines(sock, 4) == [
            "could not understand: 'make coffee'",
            "File not found: notes.txt",
            "URSoftware 5.21.0.0 (armfleet)",
            "Disconnected",
        ]
        assert sock.recv(10) == b""  # closed after quit


def test_a_paused_world_driven_through_the_table_stops_and_restart_safety_clears_it(ur) -> None:
    """On a paused server: REST targets that put the gripper 8 cm into the table are taken, one
    step carries them out and the table check stops the world (the arm held, the Dashboard
    and the world's state say so, REST moves refused); `restart safety` clears it at once,
    with no tick between, and the world's state reads NORMAL straight away."""
    server, addrs = ur
    dash = dashboard_client.DashboardClient(addrs[1])
    dash.connect()
    http = httpx.Client(base_url=server.url, timeout=10)
    try:
        home = http.get("/v1/worlds/1/state").json()["target"]
        down = {"name": ["shoulder_lift_joint"], "position": [home[1] + 0.4]}
        assert http.put("/v1/worlds/1/targets", json=down).status_code == 200
        assert http.post("/v1/sim/step", json={"ticks": 1}).status_code == 200
        wait_for(lambda: dash.safetystatus() == "Safetystatus: PROTECTIVE_STOP", "the stop")
        state = http.get("/v1/worlds/1/state").json()
        assert state["safety_mode"] == "PROTECTIVE_STOP"
        assert abs(state["target"][1] - home[1]) < 0.05  # held near home, not 0.4 rad down
        refused = http.put("/v1/worlds/1/targets", json=down)
        assert refused.status_code == 409 and "table" in refused.json()["detail"]
        assert http.get("/v1/worlds/0/state").json()["safety_mode"] == "NORMAL"
        tick = state["tick"]
        dash.restartSafety()
        state = http.get("/v1/worlds/1/state").json()
        assert state["safety_mode"] == "NORMAL" and state["tick"] == tick  # no tick between
        assert dash.robotmode() == "Robotmode: POWER_OFF"  # as the robot: power on again
        dash.powerOn()
        dash.brakeRelease()
        assert (
            http.put(
                "/v1/worlds/1/targets",
                json={"name": ["shoulder_lift_joint"], "position": [home[1]]},
            ).status_code
            == 200
        )
    finally:
        dash.disconnect()
        http.close()
