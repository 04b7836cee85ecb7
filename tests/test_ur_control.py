"""ur_rtde's control interface and URScript lines against every world, judged by the registry's
ur-rtde 1.6.5 wheel unchanged (RTDEControlInterface, RTDEReceiveInterface, DashboardClient)
over real sockets to a real realtime server, and by raw sockets to 30001/30002 where ur_rtde
has no call: moves reach their targets, moveL keeps the TCP on its line, FK equals MuJoCo's
flange, IK round-trips, servoJ at 500 Hz is followed, a protective stop is raised, reported on
every surface and unlocked, bad register values and unknown URScript are refused with the
world unchanged, a second control connection is refused, and the other world never notices.
"""

from __future__ import annotations

import json
import math
import os
import socket
import struct
import subprocess
import sys
import threading
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from websockets.sync.client import connect

from clients import ArmfleetClient
from tests.conftest import Server, wait_for
from tests.test_ur_scripts import wheel_params
from tests.ur_judge import ur_server

rtde_control = pytest.importorskip("rtde_control")  # the `test` extra: ur-rtde==1.6.5
rtde_receive = pytest.importorskip("rtde_receive")
dashboard_client = pytest.importorskip("dashboard_client")

BASE_Z = 0.5
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


@pytest.fixture(scope="module")
def ur(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, list[str]]]:
    extra = ("--control-hz", "500")  # the controller rate of an e-Series, as ur_rtde expects
    with ur_server(2, tmp_path_factory.mktemp("ur-control"), extra, mode="realtime") as pair:
        yield pair


@pytest.fixture
def arm(ur) -> Iterator[tuple[object, object, str, Server]]:
    server, addrs = ur
    c = rtde_control.RTDEControlInterface(addrs[0])
    r = rtde_receive.RTDEReceiveInterface(addrs[0])
    try:
        yield c, r, addrs[0], server
    finally:
        c.disconnect()
        r.disconnect()


def _targets(server: Server, world: int) -> list[float]:
    return httpx.get(f"{server.url}/v1/worlds/{world}/state").json()["target"][:6]


def _settled_targets(server: Server, world: int) -> list[float] | None:
    """The world's targets once a move has set its last one (the TCP arrives within a
    millimetre a few ticks before its line's ramp ends): the same over two ticks or more."""
    first = _targets(server, world)
    time.sleep(0.05)
    return first if _targets(server, world) == first else None


def fresh(r) -> None:
    """Wait for RTDE packages sent after now: ur_rtde's receive interface answers from the last
    package its thread has read, which on a loaded box is some ticks old (4 mm behind a moveL's
    last millimetres at load 10)."""
    now = r.getTimestamp()
    wait_for(lambda: r.getTimestamp() >= now + 0.02, "RTDE packages 20 ms newer", 20)


def test_movej_and_movel_reach_their_targets_and_movel_keeps_to_its_line(arm) -> None:
    c, r, _, server = arm
    other = _targets(server, 1)
    q1 = [0.3, -1.4, 1.3, -1.5, -1.6, 0.2]
    assert c.moveJ(q1, 1.0, 2.0)
    fresh(r)
    assert np.abs(np.array(r.getActualQ()) - q1).max() < 1e-3
    start = np.array(r.getActualTCPPose())
    goal = start.copy()
    goal[:3] += [0.10, -0.05, -0.15]
    seen: list[list[float]] = []
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.append(r.getActualTCPPose())
            time.sleep(0.002)

    t = threading.Thread(target=watch)
    t.start()
    try:
        assert c.moveL(goal.tolist(), 0.25, 1.2)
    finally:
        done.set()
        t.join()
    fresh(r)
    end = np.array(r.getActualTCPPose())
    assert np.abs(end[:3] - goal[:3]).max() < 1e-3
    path = np.array(seen)[:, :3]
    axis = (goal[:3] - start[:3]) / np.linalg.norm(goal[:3] - start[:3])
    rel = path - start[:3]
    off = rel - np.outer(rel @ axis, axis)
    deviation = float(np.linalg.norm(off, axis=1).max())
    print(f"moveL line deviation (RTDE receive, {len(path)} samples): {deviation * 1e3:.3f} mm")
    assert deviation < 1e-3
    assert _targets(server, 1) == other  # the other world never noticed


def _flange_in_base(st: dict) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's flange pose of a world's state in the robot's base frame (the base is turned
    half a turn about z and stands at BASE_Z)."""
    x, y, z = st["flange"]["position"]
    w, qx, qy, qz = st["flange"]["quaternion"]
    rot = np.array(
        [
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * w), 2 * (qx * qz + qy * w)],
            [2 * (qx * qy + qz * w), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * w)],
            [2 * (qx * qz - qy * w), 2 * (qy * qz + qx * w), 1 - 2 * (qx * qx + qy * qy)],
        ]
    )
    return np.array([-x, -y, z - BASE_Z]), np.diag([-1.0, -1.0, 1.0]) @ rot


def test_forward_kinematics_equals_mujocos_flange_and_ik_round_trips(arm) -> None:
    """getForwardKinematics() of the current pose, (q, tcp) and (q, zero TCP) against MuJoCo's
    flange. ur-rtde 1.6.5 sends an all-zero TCP as q's command with the six zeros past its
    recipe's fields: armfleet reads the package by its recipe, as a controller does, and the
    script's get_forward_kin(q, tcp) takes the TCP from input registers 6..11 as last written
    (the guide says so): zero after a call that wrote a zero TCP there, the last TCP sent
    otherwise."""
    c, _r, _, server = arm
    assert c.moveJ([0.5, -1.2, 1.0, -1.3, -1.4, 0.4], 1.0, 2.0)
    wait_for(lambda: c.isSteady(), "steady")
    st = httpx.get(f"{server.url}/v1/worlds/0/state").json()
    q = np.asarray(st["position"][:6], np.float32).astype(np.float64)
    pos, rot = _flange_in_base(st)
    # the current pose, the active TCP (zero): a later tick than the state's, the servos
    # settling by micrometres
    np.testing.assert_allclose(c.getForwardKinematics()[:3], pos, atol=1e-4)
    flange = np.array(c.getForwardKinematics(q.tolist(), [1e-300] + [0.0] * 5))
    np.testing.assert_allclose(flange[:3], pos, atol=1e-6)
    zero = np.array(c.getForwardKinematics(q.tolist(), [0.0] * 6))  # 12 values, 6-value recipe
    np.testing.assert_allclose(zero, flange, atol=1e-12)
    tcp = [0.01, -0.02, 0.15, 0.0, 0.0, 0.3]
    fk = np.array(c.getForwardKinematics(q.tolist(), tcp))
    np.testing.assert_allclose(fk[:3], pos + rot @ tcp[:3], atol=1e-6)
    stale = np.array(c.getForwardKinematics(q.tolist(), [0.0] * 6))  # registers 6..11: tcp
    np.testing.assert_allclose(stale, fk, atol=1e-12)
    assert "the rest ignored" in server.log()
    assert c.setTcp(tcp)  # IK is of the active TCP, as the script's get_inverse_kin
    try:
        q_ik = np.array(c.getInverseKinematics(fk.tolist(), q.tolist()))
        np.testing.assert_allclose(q_ik, q, atol=1e-6)
        back = np.array(c.getForwardKinematics(q_ik.tolist(), tcp))
        np.testing.assert_allclose(back, fk, atol=1e-6)
        assert c.getInverseKinematicsHasSolution(fk.tolist())
        assert not c.getInverseKinematicsHasSolution([2.5, 0, 0, 0, 0, 0])
    finally:
        assert c.setTcp([0.0] * 6)


def test_servoj_streamed_at_500_hz_is_followed(arm) -> None:
    """10 s of servoJ at 500 Hz (ur_rtde's initPeriod/waitPeriod) along a path of simulated
    time (sample k at k x 2 ms, whatever the client's clock does): every command is taken, the
    arm passes through the path's range and stops on its last point, the program runs on and
    no protective stop is raised. The lag and the error are reported, not asserted: they are
    wall-clock properties of a shared box (bench/ measures speed)."""
    c, r, _, _ = arm
    q0 = np.array([0.0, -1.3, 1.2, -1.5, -1.57, 0.0])
    amp = np.array([0.3, 0.2, -0.2, 0.3, 0.3, 0.5])
    assert c.moveJ(q0.tolist(), 1.0, 2.0)
    sent, got, taken = [], [], []
    start = time.perf_counter()
    for k in range(5000 + 250):  # 10 s at 500 Hz, then 0.5 s holding the last point
        t0 = c.initPeriod()
        q = q0 + amp * math.sin(2 * math.pi * 0.25 * min(k, 5000) * 0.002)
        taken.append(c.servoJ(q.tolist(), 0.5, 0.5, 0.002, 0.1, 300))
        sent.append((time.perf_counter() - start, q))
        got.append((time.perf_counter() - start, np.array(r.getActualQ())))
        c.waitPeriod(t0)
    last = sent[-1][1]
    wait_for(lambda: np.abs(np.array(r.getActualQ()) - last).max() < 1e-3, "on the last point")
    end = np.array(r.getActualQ())  # the arm came to its last point (servoStop then stops it)
    assert c.servoStop(2.0)
    ts = np.array([s[0] for s in sent[:5000]])
    cmd = np.array([s[1] for s in sent[:5000]])
    act = np.array([g[1] for g in got[:5000]])
    half = len(ts) // 2  # after the start-up
    lags = np.arange(0, 0.3, 0.004)
    errs = [
        np.abs(
            act[half:] - np.array([np.interp(ts[half:] - lag, ts, cmd[:, j]) for j in range(6)]).T
        ).max()
        for lag in lags
    ]
    best = int(np.argmin(errs))
    raw = float(np.abs(act[half:] - cmd[half:]).max())
    print(
        f"servoJ 500 Hz x 10 s: sent in {ts[-1]:.2f} s ({len(ts) / ts[-1]:.0f} Hz), lag "
        f"{lags[best] * 1e3:.0f} ms, error after lag {errs[best]:.4f} rad, at the same "
        f"instant {raw:.4f} rad"
    )
    assert all(taken)  # no command refused
    assert c.isProgramRunning() and r.getSafetyMode() == 1  # NORMAL: no protective stop
    assert np.abs(end - last).max() < 1e-3
    reached = act.max(axis=0) - act.min(axis=0)  # the arm went through the path's range
    assert (reached > 1.9 * np.abs(amp) * 0.9).all(), reached


def _safety_on_every_surface(server: Server, r, dash, world: int = 0) -> dict[str, object]:
    """The world's safety mode as RTDE, the Dashboard, REST (state and TCP), the WebSocket
    state frames (of a tick after the REST read: a frame is stamped when its tick is
    published), GET /v1/ur and the Python client (REST, and the binary batch frames it
    parses) each report it."""
    rest = httpx.get(f"{server.url}/v1/worlds/{world}/state").json()  # as of now
    with connect(f"{server.ws_url}/v1/ws/worlds/{world}") as ws:
        while (frame := json.loads(ws.recv(timeout=5)))["op"] != "state" or (
            frame["tick"] <= rest["tick"]
        ):
            pass
    with connect(f"{server.ws_url}/v1/ws?worlds=0-1") as ws:
        while (batch := json.loads(ws.recv(timeout=5)))["op"] != "states" or (
            batch["tick"] <= rest["tick"]
        ):
            pass
    client = ArmfleetClient(server.url)
    rows = client.states([0, 1])
    assert client.state(world).safety_mode == rows.world(world).safety_mode  # the Python client
    for binary in client.stream([0, 1], binary=True, reconnect=False):  # float32 frames
        if binary.tick > rest["tick"]:
            break
    return {
        "rtde": (r.getSafetyMode(), bool(r.getSafetyStatusBits() & (1 << 2))),
        "dashboard": (dash.safetystatus(), dash.safetymode()),
        "rest": rest["safety_mode"],
        "tcp": httpx.get(f"{server.url}/v1/worlds/{world}/tcp").json()["safety_mode"],
        "ws": (frame["safety_mode"], batch["safety_mode"][batch["worlds"].index(world)]),
        "ur": httpx.get(f"{server.url}/v1/ur").json()["worlds"][world]["safety_mode"],
        "client": rows.world(world).safety_mode,
        "binary": binary.world(world).safety_mode,
    }


def _reported_everywhere(mode: str, rtde_mode: int) -> dict[str, object]:
    """What `_safety_on_every_surface` reads for a world in safety mode `mode`: the same name
    on every surface, RTDE's number for it with the protective-stop status bit, the
    Dashboard's two lines."""
    return {
        "rtde": (rtde_mode, mode == "PROTECTIVE_STOP"),
        "dashboard": (f"Safetystatus: {mode}", f"Safetymode: {mode}"),
        "rest": mode,
        "tcp": mode,
        "ws": (mode, mode),
        "ur": mode,
        "client": mode,
        "binary": mode,
    }


STOPPED = _reported_everywhere("PROTECTIVE_STOP", 3)
NORMAL = _reported_everywhere("NORMAL", 1)
PADS_OVER_TABLE = 0.215  # m between the gripper's pads and the table top at HOME


def test_driving_through_the_table_is_a_protective_stop_reported_everywhere_and_unlocked(
    arm,
) -> None:
    """moveL straight down beside the cube, 10 cm into the table: the world is protective-
    stopped before the gripper's pads are 1 cm in, the arm holds there, every surface says
    PROTECTIVE_STOP, REST refuses to move it (409), the Dashboard refuses to unlock it within
    5 s of the stop and unlocks it after, and then the program moves the arm back up."""
    c, r, addr, server = arm
    dash = dashboard_client.DashboardClient(addr)
    dash.connect()
    try:
        assert c.moveJ(HOME, 1.0, 2.0)
        above = np.array(r.getActualTCPPose())
        above[1] += 0.15  # beside the cube, still over the table
        assert c.moveL(above.tolist(), 0.25, 1.2)
        assert _safety_on_every_surface(server, r, dash) == NORMAL
        down = above.copy()
        down[2] -= PADS_OVER_TABLE + 0.10  # the pads 10 cm into the table
        assert c.moveL(down.tolist(), 0.25, 1.2, True)  # asynchronous: it will not finish
        wait_for(lambda: r.isProtectiveStopped(), "a protective stop", timeout=20)
        seen = time.monotonic()
        # at once (the 5 s count from the stop; every surface's reads below take their time)
        with pytest.raises(RuntimeError, match="5s after"):  # within 5 s: the robot's refusal
            dash.unlockProtectiveStop()
        assert _safety_on_every_surface(server, r, dash) == STOPPED
        held = np.array(r.getActualTCPPose())
        assert held[2] > down[2] + 0.08  # stopped with the pads at most 2 cm in, not 10
        assert not c.isProgramRunning()
        bad = httpx.put(
            f"{server.url}/v1/worlds/0/targets", json={"name": ["elbow_joint"], "position": [1.0]}
        )
        assert bad.status_code == 409 and "protective" in bad.json()["detail"], bad.text
        assert "into table_top" in server.log()  # the service log says why
        assert np.abs(np.array(r.getActualTCPPose())[:3] - held[:3]).max() < 1e-3  # it holds

        def unlocked() -> bool:
            try:
                dash.unlockProtectiveStop()
            except RuntimeError:
                time.sleep(0.1)
                return False
            return True

        wait_for(unlocked, "the unlock accepted", timeout=10)
        assert time.monotonic() - seen > 4.5
        wait_for(lambda: not r.isProtectiveStopped(), "unlocked")
        assert _safety_on_every_surface(server, r, dash) == NORMAL
        assert c.reuploadScript()
        wait_for(lambda: c.isProgramRunning(), "the script runs again")
        assert c.moveL(above.tolist(), 0.25, 1.2)  # back up: out of the table is allowed
        assert _safety_on_every_surface(server, r, dash, world=1) == NORMAL  # never noticed
    finally:
        dash.disconnect()


def test_trigger_protective_stop_is_reported_and_a_reset_clears_it(arm) -> None:
    c, r, addr, server = arm
    dash = dashboard_client.DashboardClient(addr)
    dash.connect()
    try:
        c.triggerProtectiveStop()
        wait_for(lambda: r.isProtectiveStopped(), "RTDE reports the stop")
        with pytest.raises(RuntimeError, match="5s after"):  # within 5 s: the robot's refusal
            dash.unlockProtectiveStop()
        assert _safety_on_every_surface(server, r, dash) == STOPPED
        ur = httpx.get(f"{server.url}/v1/ur").json()["worlds"][0]
        assert ur["program_state"] == "STOPPED"
        assert not c.isProgramRunning() and not dash.running()
        assert not c.moveJ(HOME, 1.0, 1.0)  # refused while stopped
        assert httpx.post(f"{server.url}/v1/worlds/0/reset").status_code == 200
        wait_for(lambda: not r.isProtectiveStopped(), "a reset clears the stop")
        assert _safety_on_every_surface(server, r, dash) == NORMAL
        assert c.reuploadScript()
        wait_for(lambda: c.isProgramRunning(), "the script runs again")
        assert dash.running()
        assert c.moveJ(HOME, 1.0, 2.0)
    finally:
        dash.disconnect()


def test_bad_register_values_and_a_second_control_connection_are_refused(arm) -> None:
    c, _r, addr, server = arm
    before = _targets(server, 0)
    other = _targets(server, 1)
    assert not c.moveJ([math.nan, -1.5, 1.5, -1.5, -1.5, 0.0], 1.0, 1.0)
    assert not c.moveJ([40.0, -1.5, 1.5, -1.5, -1.5, 0.0], 1.0, 1.0)
    assert _targets(server, 0) == before and _targets(server, 1) == other
    assert c.reuploadScript()
    wait_for(lambda: c.isProgramRunning(), "running again")
    with pytest.raises(RuntimeError):
        rtde_control.RTDEControlInterface(addr)
    assert c.moveJ(HOME, 1.0, 2.0)


def _robot_messages(sock: socket.socket, want: str, timeout: float = 5.0) -> str:
    sock.settimeout(timeout)
    buf = b""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        buf += sock.recv(65536)
        while len(buf) >= 5:
            size, kind = struct.unpack(">iB", buf[:5])
            if len(buf) < size:
                break
            body, buf = buf[5:size], buf[size:]
            if kind == 20 and want in body[10:].decode():
                return body[10:].decode()
    raise AssertionError(f"no robot message with {want!r}")


def test_urscript_lines_move_the_arm_and_unknown_functions_are_refused(ur) -> None:
    server, addrs = ur
    r = rtde_receive.RTDEReceiveInterface(addrs[1])
    log_port = socket.create_connection((addrs[1], 30001), timeout=5)
    script = socket.create_connection((addrs[1], 30002), timeout=5)
    try:
        q = [0.2, -1.4, 1.4, -1.6, -1.5, 0.1]
        script.sendall(f"movej({q}, a=2.0, v=1.0)\n".encode())
        wait_for(lambda: np.abs(np.array(r.getActualQ()) - q).max() < 2e-3, "movej line")
        pose = r.getActualTCPPose()
        pose[2] += 0.05
        script.sendall(f"movel(p{pose}, a=1.2, v=0.25)\n".encode())
        wait_for(lambda: abs(r.getActualTCPPose()[2] - pose[2]) < 1e-3, "movel line")
        before = wait_for(lambda: _settled_targets(server, 1), "the movel line's last target")
        script.sendall(b"set_digital_out(1, True)\n")
        text = _robot_messages(log_port, "set_digital_out")
        assert "not carried out" in text
        script.sendall(b"movej([0, 0, 0], a=1)\n")
        assert "6 finite numbers" in _robot_messages(log_port, "movej")
        assert _targets(server, 1) == before
        assert "set_digital_out" in server.log()  # and the service log names it
    finally:
        log_port.close()
        script.close()
        r.disconnect()


# One short program, unchanged, as a user of each release writes it (run with that release's
# modules first on the path): moveJ, moveL down, IK of the pose before it and a moveJ there,
# FK of where the arm is, moveJ home.
RELEASE_PROGRAM = """
import sys, rtde_control, rtde_receive
addr, home = sys.argv[1], [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
c = rtde_control.RTDEControlInterface(addr)
r = rtde_receive.RTDEReceiveInterface(addr)
q = [0.3, -1.4, 1.3, -1.5, -1.6, 0.2]
assert c.moveJ(q, 1.0, 2.0)
assert max(abs(a - b) for a, b in zip(r.getActualQ(), q)) < 1e-3, r.getActualQ()
p = r.getActualTCPPose()
down = list(p)
down[2] -= 0.05
assert c.moveL(down, 0.25, 1.2) and abs(r.getActualTCPPose()[2] - down[2]) < 1e-3
assert c.getInverseKinematicsHasSolution(p)
assert c.moveJ(c.getInverseKinematics(p, r.getActualQ()), 1.0, 2.0)
assert max(abs(a - b) for a, b in zip(r.getActualTCPPose()[:3], p[:3])) < 1e-3
assert max(abs(a - b) for a, b in zip(c.getForwardKinematics(), r.getActualTCPPose())) < 1e-3
assert c.moveJ(home, 1.0, 2.0) and c.isProgramRunning()
c.stopScript()
c.disconnect()
r.disconnect()
"""


@pytest.mark.parametrize("wheel", wheel_params())
def test_each_ur_rtde_1_6_release_drives_a_world(ur, wheel: Path, tmp_path: Path) -> None:
    """Each 1.6.x release's RTDEControlInterface + RTDEReceiveInterface, unchanged, moves a
    world (the registry's wheels from ARMFLEET_UR_RTDE_WHEELS; test_ur_scripts.py's docstring
    says how to fetch them): the guide's list of releases is what passed here."""
    server, addrs = ur
    with zipfile.ZipFile(wheel) as z:
        z.extractall(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}  # the release's modules first
    cmd = [sys.executable, "-c", RELEASE_PROGRAM, addrs[0]]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    release = wheel.name.split("-")[1]
    started = [line for line in server.log().splitlines() if "running natively" in line]
    assert release in started[-1]  # the recogniser named the release that uploaded it
