"""armfleet on one host, ROS on another: the node reaches armfleet by URL, DDS stays on the ROS
host. Two network namespaces made here, joined by a veth pair (10.217.18.1 <-> .2, IPv6 off):
`armfleet serve` (no ROS there) in one; the armfleet_ros node, started first, and a judge node
(the seed's controller) in the other, both on real rclpy with LOCALHOST discovery. Needs root
and `ip` (iproute2); skipped with the reason otherwise."""

from __future__ import annotations

import contextlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import pytest

from tests import ros2_judge
from tests.conftest import ROOT, wait_for

pytestmark = pytest.mark.skipif(
    ros2_judge.skip_reason() is not None, reason=str(ros2_judge.skip_reason())
)
ADDRESSES = ("10.217.18.1", "10.217.18.2")
PORT = 8000  # a namespace of our own: every port is free


class Hosts:
    """Two namespaces, 'armfleet' and 'ros', joined by a veth pair."""

    def __init__(self) -> None:
        tag = f"{os.getpid() % 10000}{random.randrange(100)}"
        self.ns = {"armfleet": f"af18-{tag}-a", "ros": f"af18-{tag}-r"}
        self.dev = {"armfleet": f"ag{tag}a", "ros": f"ag{tag}r"}

    def up(self) -> None:
        a, r = self.ns["armfleet"], self.ns["ros"]
        for ns in (a, r):
            _ip("netns", "add", ns)
        _ip("link", "add", self.dev["armfleet"], "netns", a, "type", "veth",
            "peer", "name", self.dev["ros"], "netns", r)  # fmt: skip
        for (host, ns), address in zip(self.ns.items(), ADDRESSES, strict=True):
            dev = self.dev[host]
            for key in ("all", "default", dev):
                _ip("netns", "exec", ns, "sysctl", "-qw", f"net.ipv6.conf.{key}.disable_ipv6=1")
            _ip("-n", ns, "addr", "add", f"{address}/24", "dev", dev)
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", ns, "link", "set", dev, "up")

    def down(self) -> None:
        for ns in self.ns.values():
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)

    def run(self, host: str, *cmd: str) -> list[str]:
        return ["ip", "netns", "exec", self.ns[host], *cmd]

    def get(self, path: str) -> Any:
        cmd = self.run("armfleet", "curl", "-sf", "--max-time", "5", f"{URL}{path}")
        done = subprocess.run(cmd, capture_output=True, text=True)
        return json.loads(done.stdout) if done.returncode == 0 else None


URL = f"http://{ADDRESSES[0]}:{PORT}"


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    if os.geteuid() != 0 or not (shutil.which("ip") and shutil.which("curl")):
        pytest.skip("two hosts need root, `ip` (iproute2) and curl to make network namespaces")
    h = Hosts()
    try:
        h.up()
    except subprocess.CalledProcessError as exc:
        h.down()
        pytest.skip(f"network namespaces cannot be made here: {exc.stderr.strip()}")
    yield h
    h.down()


@contextlib.contextmanager
def process(cmd: list[str], env: dict[str, str], log: Any) -> Iterator[subprocess.Popen[bytes]]:
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
    try:
        yield proc
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_node_on_the_ros_host_drives_armfleet_on_another(hosts: Hosts, tmp_path: Any) -> None:
    ros_env = ros2_judge.node_env()
    node_cmd = [ros2_judge.python(), "-m", "armfleet_ros.node", "--ros-args"]
    node_cmd += ["-p", f"url:={URL}", "-p", "worlds:=1"]
    serve_cmd = [sys.executable, "-m", "service.cli", "serve", "--worlds", "2", "--engine"]
    serve_cmd += ["mujoco", "--host", ADDRESSES[0], "--port", str(PORT), "--insecure"]
    af_env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_")}
    af_env.update(PYTHONPATH=str(ROOT), ARMFLEET_DATA_DIR=str(tmp_path / "data"))
    with (
        open(tmp_path / "node.log", "ab") as node_log,
        open(tmp_path / "armfleet.log", "ab") as af_log,
        process(hosts.run("ros", *node_cmd), ros_env, node_log),  # the node first
    ):
        time.sleep(2)
        with process(hosts.run("armfleet", *serve_cmd), af_env, af_log):
            wait_for(lambda: hosts.get("/readyz"), "armfleet ready on its host", 120)
            wait_for(
                lambda: ((hosts.get("/v1/ros") or {}).get("node") or {}).get("report"),
                "the node's report from the ROS host",
                60,
            )
            judge = [ros2_judge.python(), str(ros2_judge.JUDGE_SCRIPT), "seed", "/world_1", "0.4"]
            done = subprocess.run(
                hosts.run("ros", *judge), env=ros2_judge.env(), capture_output=True, text=True,
                timeout=90,
            )  # fmt: skip
            seen = json.loads(done.stdout.splitlines()[-1])
            assert seen["reached"], done.stderr
            assert hosts.get("/v1/worlds/1/state")["target"][6] == 0.4
    assert b"waiting for armfleet" in (tmp_path / "node.log").read_bytes()
