"""The armfleet_ros node's supervision and start orders, each test with an armfleet (and a ROS
graph, `OWN_GRAPH`) of its own, judged by real rclpy as in tests/test_ros_node.py: the node
restarts when it dies, waits for an armfleet started after it, serves Isaac's remapped
contract at 500 Hz, and `serve --ros2` without ROS says so in one line.

A file of their own, not tests/test_ros_node.py's: that module's server and node (about 0.13
CPU-s a second) are stopped when its shared tests are done rather than idle through these, and
pytest-xdist gives the two files to two workers.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from typing import Any

import httpx
import pytest

from tests import ros2_judge
from tests.conftest import free_port, serve, wait_for
from tests.test_ros_node import OWN_GRAPH, judge, node_report, ros_server, targets

pytestmark = pytest.mark.skipif(
    ros2_judge.skip_reason() is not None, reason=str(ros2_judge.skip_reason())
)


# -- supervision and start orders ----------------------------------------------------------------


def test_node_restarts_when_it_dies_and_readyz_says_so(tmp_path: Any) -> None:
    with (
        ros_server(log_dir=tmp_path, domain=OWN_GRAPH) as srv,
        httpx.Client(base_url=srv.url, timeout=10) as http,
    ):
        pid = node_report(http)["pid"]
        os.kill(pid, signal.SIGKILL)

        def degraded() -> dict[str, Any] | None:
            r = http.get("/readyz")
            return r.json() if r.status_code == 503 else None

        ready = wait_for(degraded, "/readyz naming the dead node", 30)
        assert "ROS 2 node exited" in ready["detail"]
        node = wait_for(
            lambda: (n := node_report(http)) and n["pid"] != pid and n, "a new node", 30
        )
        assert node["restarts"] == 1 and node["last_exit"] == -signal.SIGKILL
        assert http.get("/readyz").status_code == 200
        assert judge("seed", "", "0.3", domain=OWN_GRAPH)["reached"]
        assert targets(http, 0)[6] == 0.3
        new_pid = node["pid"]
    with contextlib.suppress(ProcessLookupError):
        os.kill(new_pid, 0)
        pytest.fail("the node outlived armfleet")
    assert "ROS 2 node exited with status -9" in srv.log_path.read_text()


def test_node_started_before_armfleet(tmp_path: Any) -> None:
    """The node waits for armfleet, whichever starts first (here: the node, standalone).
    Its `play_mode:=fast` is what simulation_interfaces' PLAYING then puts armfleet in."""
    port = free_port()
    cmd = [ros2_judge.python(), "-m", "armfleet_ros.node", "--ros-args"]
    cmd += ["-p", f"url:=http://127.0.0.1:{port}", "-p", "worlds:=0-1"]
    cmd += ["-p", "play_mode:=fast"]
    node = subprocess.Popen(
        cmd,
        env=ros2_judge.on_domain(ros2_judge.node_env(), OWN_GRAPH),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    out: list[bytes] = []
    assert node.stdout is not None
    reader = threading.Thread(target=lambda: out.extend(iter(node.stdout.readline, b"")))
    reader.start()
    try:
        # Armfleet starts once the node says it waits (not after a fixed 3 s: a node still
        # importing rclpy on a loaded box would find armfleet up and never wait for it).
        wait_for(
            lambda: b"waiting for armfleet" in b"".join(out), "the node to wait for armfleet", 120
        )
        assert node.poll() is None
        args = ["--engine", "mujoco"]
        with (
            serve(worlds=2, port=port, extra_args=args, log_dir=tmp_path) as srv,
            httpx.Client(base_url=srv.url, timeout=10) as http,
        ):
            seen = judge("seed", "/world_1", "0.25", domain=OWN_GRAPH)
            assert seen["reached"]
            assert targets(http, 1)[6] == 0.25
            paused, playing = judge("states", "2", "1", domain=OWN_GRAPH)["steps"]
            assert paused["result"][0] == playing["result"][0] == 1  # RESULT_OK
            assert (paused["state"], playing["state"]) == (2, 1)
            assert http.get("/v1/info").json()["mode"] == "fast"  # PLAYING: the play_mode
    finally:
        node.send_signal(signal.SIGINT)
        # the node's own stop allows its lanes 5 s and its stream thread 5 s (link.py), then
        # rclpy shuts down: 15 s was tighter than that and failed twice on this 2-core box
        # with armfleet already gone; a node that does not stop still fails here
        node.wait(timeout=60)
        reader.join(timeout=15)
    assert b"waiting for armfleet" in b"".join(out)


def ticked(http: httpx.Client) -> int:
    """The server's tick now (world 0's state)."""
    return int(http.get("/v1/worlds/0/state").json()["tick"])


def test_isaac_contract_by_remapping(tmp_path: Any) -> None:
    """ur_description's `sim_isaac` mode: topic_based_ros2_control publishes full JointState
    commands on /isaac_joint_commands at the controller rate and reads /isaac_joint_states.
    Remapping world 0's topics is all it takes; 500 Hz for 3 s: every message applied."""
    port = free_port()
    cmd = [ros2_judge.python(), "-m", "armfleet_ros.node", "--ros-args"]
    cmd += ["-p", f"url:=http://127.0.0.1:{port}", "-p", "rate:=100.0"]
    cmd += ["-r", "/joint_commands:=/isaac_joint_commands"]
    cmd += ["-r", "/joint_states:=/isaac_joint_states"]
    env = ros2_judge.on_domain(ros2_judge.node_env(), OWN_GRAPH)
    args = ["--engine", "mujoco"]
    with (
        serve(worlds=2, port=port, extra_args=args, log_dir=tmp_path) as srv,
        httpx.Client(base_url=srv.url, timeout=10) as http,
    ):
        node = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        try:
            node_report(http)
            tick0, t0 = ticked(http), time.monotonic()
            seen = judge("isaac", "500", "3", domain=OWN_GRAPH)
            # the server's own ticks a second over the judge's run (60 a second in real time;
            # fewer where a loaded box slows it): states can come back no faster than that
            ticks_per_s = (ticked(http) - tick0) / (time.monotonic() - t0)

            def handled() -> dict[str, Any] | None:  # the node's report comes every so often
                report = node_report(http)["report"]
                done = report["accepted"] + sum(report["rejected"].values())
                return report if done >= seen["sent"] else None

            with contextlib.suppress(AssertionError):  # else the assertion names what is not
                wait_for(handled, "the node to report every message handled", 30)
            report = node_report(http)["report"]
            assert report["accepted"] == seen["sent"] == 1500 and not report["rejected"], report
            assert targets(http, 0)[6] == pytest.approx(seen["last"], abs=1e-12)
            # states back at the node's rate (100 Hz asked), which the 60 Hz ticks bound. The
            # node is a Python process sharing the box: with the suite's other workers on 2
            # cores it forwarded 47 of 60 a second once (0.78), so the bar is 0.6 of the
            # ticks: a node that forwards every other state (30 of 60) still fails it
            assert seen["states_per_s"] > 0.6 * min(100.0, ticks_per_s), (seen, ticks_per_s)
        finally:
            node.send_signal(signal.SIGINT)
            node.communicate(timeout=15)


def test_no_ros_is_one_line(tmp_path: Any) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("ROS_DISTRO", "AMENT_PREFIX_PATH")}
    done = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve", "--ros2", "--port", str(free_port())],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ros2_judge.ROOT,
    )
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "source /opt/ros/<distro>/setup.bash" in lines[0], done.stderr
