"""With leases on, a world's UR ports are open only while the world is lent: a connection to
a world that is not lent is closed at once; while lent, ur-rtde 1.6.5 receives from it; when
the lease ends, its connections are closed and its controller is fresh for the next holder.
RTDE and the Dashboard carry no token, so the lease is the only gate (the guide says so).

And the `armfleet_ur_world` fixture against one shared lending server, as a CI suite uses it:
`pytest -n 4` of a small test file, each worker's test on a world and UR address of its own,
driven through ur-rtde 1.6.5 (receive, and a control-interface or URScript move).

One 4-world realtime server (native MuJoCo) for the module, `--token` the administrator's.
"""

from __future__ import annotations

import os
import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from service.core.process.engine_priority import COMPANION_STEPS
from service.core.sim.command_share import REQUESTS_NICE
from tests.conftest import HOME, Server, wait_for
from tests.test_engine_priority import RAISED_LINE, REFUSED_LINE, may_raise_to, task_nices
from tests.test_leases import pytest_n4
from tests.ur_judge import DASHBOARD, RTDE, RawRtde, ur_server

rtde_receive = pytest.importorskip("rtde_receive")  # the `test` extra: ur-rtde==1.6.5
ADMIN = "admin-" + "u" * 26
AUTH = {"Authorization": f"Bearer {ADMIN}"}
NWORLD = 4


@pytest.fixture(scope="module")
def ur(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, list[str]]]:
    extra = ("--token", ADMIN, "--leases", "optional")
    log_dir = tmp_path_factory.mktemp("ur-leases")
    with ur_server(NWORLD, log_dir, extra, mode="realtime") as pair:
        yield pair


def _closed_at_once(host: str, port: int) -> bool:
    with socket.create_connection((host, port), timeout=5) as sock:
        try:
            return sock.recv(100) == b""
        except ConnectionResetError:
            return True


def _open(server: Server, world: int) -> bool:
    return bool(httpx.get(f"{server.url}/v1/ur").json()["worlds"][world]["open"])


def test_ports_open_only_while_the_world_is_lent(ur) -> None:
    server, addrs = ur
    assert not _open(server, 1)
    assert _closed_at_once(addrs[1], RTDE) and _closed_at_once(addrs[1], DASHBOARD)
    r = httpx.post(f"{server.url}/v1/leases", json={"worlds": [1], "ttl_s": 60}, headers=AUTH)
    assert r.status_code == 201, r.text
    lease = r.json()["id"]
    wait_for(lambda: _open(server, 1), "the lent world's ports open")
    assert not _open(server, 0)  # not lent: still closed
    rx = rtde_receive.RTDEReceiveInterface(addrs[1])
    raw = RawRtde(addrs[1])
    try:
        assert len(rx.getActualQ()) == 6
        raw.handshake()
        assert httpx.delete(f"{server.url}/v1/leases/{lease}", headers=AUTH).status_code == 200
        with pytest.raises((ConnectionError, OSError)):
            for _ in range(100):
                raw.read()
        wait_for(lambda: not _open(server, 1), "closed again")
        assert _closed_at_once(addrs[1], RTDE)
        assert "the lease of world 1 ended" in server.log()
    finally:
        raw.close()
        rx.disconnect()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="priority is per thread on Linux")
def test_the_ur_thread_keeps_the_process_priority_when_requests_give_way(ur) -> None:
    """In real time the request thread gives the cores to the ticks (a nice step down); the
    UR ports' thread does not: ur_rtde drops a connection 2.5 s after its last package. Where
    the engine is raised (below), the UR thread is raised with it, COMPANION_STEPS, no more."""
    server, _ = ur
    base = os.getpriority(os.PRIO_PROCESS, os.getpid())  # the server started with ours
    to = may_raise_to(base)
    assert os.getpriority(os.PRIO_PROCESS, server.process.pid) == min(19, base + REQUESTS_NICE)
    ur_nice = base if to is None else max(to, base - COMPANION_STEPS)
    assert httpx.get(f"{server.url}/v1/ur").json()["thread_nice"] == ur_nice


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="priority is per thread on Linux")
def test_the_engine_thread_runs_raised_in_real_time_when_permitted(ur) -> None:
    """`--engine-priority auto` (the default): where the kernel lets this process raise a thread
    (root, CAP_SYS_NICE, RLIMIT_NICE), the server's threads above the process's priority are
    exactly the engine's (the sim thread: 4 native worlds step on it alone), at the raised nice
    GET /v1/ur reports and the log names, and the UR ports' thread, below it; where it does
    not, none is and the log says why."""
    server, _ = ur
    base = os.getpriority(os.PRIO_PROCESS, os.getpid())
    to = may_raise_to(base)
    status = httpx.get(f"{server.url}/v1/ur").json()
    engine = status["engine_priority"]
    kernel = task_nices(server.process.pid)
    above = {tid: nice for tid, nice in kernel.items() if nice < base}
    if to is None:
        assert engine["permitted"] is False and not above and REFUSED_LINE in server.log()
        return
    assert engine["setting"] == "auto" and engine["raised"] and engine["raised_nice"] == to
    assert len(engine["threads"]) == 1 and len(engine["companions"]) == 1
    ur_thread = engine["companions"][0]["id"]
    assert above == {engine["threads"][0]["id"]: to, ur_thread: max(to, base - COMPANION_STEPS)}
    assert status["thread_nice"] == above[ur_thread]
    assert f"{RAISED_LINE} {to} in real time" in server.log()


def test_rtde_keeps_flowing_while_the_ticks_stop(ur) -> None:
    """Paused for 3 s (longer than ur_rtde's 2.5 s without data), a lent world's RTDE stream
    sends its last state again: ur-rtde 1.6.5 stays connected, its timestamp that tick's, and
    moves on when the ticks do; GET /v1/ur says the longest its clients went without data."""
    server, addrs = ur
    r = httpx.post(f"{server.url}/v1/leases", json={"worlds": [2], "ttl_s": 60}, headers=AUTH)
    assert r.status_code == 201, r.text
    lease = r.json()["id"]
    try:
        wait_for(lambda: _open(server, 2), "the lent world's ports open")
        before = httpx.get(f"{server.url}/v1/ur").json()
        rx = rtde_receive.RTDEReceiveInterface(addrs[2])
        try:
            httpx.post(f"{server.url}/v1/sim/pause", headers=AUTH).raise_for_status()

            def settled() -> float | None:  # the packages of the paused tick have arrived
                first = rx.getTimestamp()
                time.sleep(0.1)
                return first if rx.getTimestamp() == first else None

            stopped = wait_for(settled, "the stream at the paused tick")
            time.sleep(3.0)  # the subject: time passing with no tick
            assert rx.isConnected() and rx.getTimestamp() == stopped
            httpx.post(f"{server.url}/v1/sim/resume", headers=AUTH).raise_for_status()
            wait_for(lambda: rx.getTimestamp() > stopped, "the stream follows the ticks again")
            after = httpx.get(f"{server.url}/v1/ur").json()
            assert 0 < after["worlds"][2]["rtde_longest_gap_s"] < 2.5
            # the service's own account: the packages it sent over the 3 s (500 Hz), the UR
            # thread's CPU, and the pause is no gap of the ticks
            assert after["rtde_packages_sent"] - before["rtde_packages_sent"] > 100
            assert after["thread_cpu_s"] > before["thread_cpu_s"]
            assert after["tick_gaps"]["longest_s"] < 3.0
        finally:
            rx.disconnect()
    finally:
        httpx.post(f"{server.url}/v1/sim/resume", headers=AUTH)
        httpx.delete(f"{server.url}/v1/leases/{lease}", headers=AUTH)


# Test i moves a joint of its own, MOVES[i] (joint, step; each away from the table): at its end
# no other world may hold that joint anywhere but home, whatever the other tests are doing to
# theirs at that moment.
MOVES = [(0, 0.2), (1, -0.2), (5, 0.2), (3, -0.2)]
XDIST_UR_TESTS = """
import json, os, socket, time
import httpx
import numpy as np
import pytest

rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")
HOME, MOVES = {home}, {moves}
ADMIN = {{"Authorization": "Bearer " + os.environ["ARMFLEET_TOKEN"]}}


def until(pred, what, timeout=30):
    deadline = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < deadline, what
        time.sleep(0.02)


@pytest.mark.parametrize("i", range(4))
def test_own_ur_world(armfleet_ur_world, i):
    ur, url = armfleet_ur_world, armfleet_ur_world.url
    arm, w = ur.client, ur.world
    started = time.time()
    r = rtde_receive.RTDEReceiveInterface(ur.address)
    try:
        home = arm.state(w).position[:6]
        assert np.abs(np.subtract(r.getActualQ(), home)).max() < 1e-3  # RTDE reads the world
        joint, step = MOVES[i]
        goal = list(HOME[:6])
        goal[joint] += step
        if i % 2 == 0:  # ur_rtde's control interface
            c = rtde_control.RTDEControlInterface(ur.address)
            try:
                assert c.moveJ(goal, 1.0, 1.4)
            finally:
                c.stopScript()
                c.disconnect()
        else:  # a line of URScript to the secondary port
            with socket.create_connection((ur.address, 30002), timeout=10) as s:
                s.sendall(("movej(" + repr(goal) + ", a=1.4, v=1.0)\\n").encode())
            until(lambda: abs(arm.state(w).target[joint] - goal[joint]) < 1e-9, "its target")
        until(lambda: np.abs(arm.state(w).position[:6] - goal).max() < 2e-3, "at the goal")
        until(lambda: np.abs(np.subtract(r.getActualQ(), arm.state(w).position[:6])).max()
              < 1e-4, "RTDE's actual_q is the REST state")
        rtde_q = r.getActualQ()
        every = httpx.get(url + "/v1/worlds/state", headers=ADMIN).json()["worlds"]
    finally:
        r.disconnect()
    with open(os.path.join({out!r}, str(i) + ".json"), "w") as f:
        json.dump({{"joint": joint, "world": w, "address": ur.address, "lease": ur.lease.id,
                   "worker": os.environ.get("PYTEST_XDIST_WORKER"), "goal": goal,
                   "rtde_q": rtde_q, "start": started, "end": time.time(),
                   "targets": {{s["world"]: s["target"] for s in every}}}}, f)
"""


def test_pytest_n4_each_worker_drives_its_own_ur_world_through_ur_rtde(ur, tmp_path: Path) -> None:
    """Four xdist workers, one test each, against the one shared server: each got its own
    world and address (the address /v1/ur gives that world), read it and moved one joint
    of it through ur-rtde 1.6.5 or a URScript line, and no other world moved that joint;
    afterwards every lease is back, every UR port closed, every world at home."""
    server, addrs = ur
    runs = pytest_n4(
        tmp_path, XDIST_UR_TESTS, server.url, ADMIN, timeout=300, home=HOME, moves=MOVES
    )
    assert len(runs) == 4 and len({r["worker"] for r in runs}) == 4
    assert len({r["world"] for r in runs}) == 4 and len({r["lease"] for r in runs}) == 4
    for r in runs:
        joint, w = r["joint"], r["world"]
        assert r["address"] == addrs[w]  # the world's own address, as /v1/ur maps it
        assert np.abs(np.subtract(r["rtde_q"], r["goal"])).max() < 2e-3, r
        own = r["targets"][str(w)]
        assert own[joint] == pytest.approx(r["goal"][joint], abs=1e-4), r
        for other, target in r["targets"].items():
            if int(other) != w:  # moved by its own test only, never on this test's joint
                assert target[joint] == pytest.approx(HOME[joint], abs=1e-9), (r, other)
    wait_for(lambda: httpx.get(f"{server.url}/v1/leases", headers=AUTH).json()["leases"] == [],
             "every lease given back")  # fmt: skip
    wait_for(lambda: not any(_open(server, w) for w in range(NWORLD)), "every UR port closed")

    def all_home() -> bool:  # each world reset when its lease ended
        state = httpx.get(f"{server.url}/v1/worlds/state", headers=AUTH).json()["worlds"]
        return all(np.allclose(s["target"], HOME, atol=1e-9) for s in state)

    wait_for(all_home, "every world back at home")
