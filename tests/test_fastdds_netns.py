"""The seed's workflow across two hosts: a Fast DDS node on one, armfleet on the other.

Two network namespaces made here, joined by a veth pair (10.217.17.1 <-> .2, IPv6 off so the
kernel itself sends nothing): `armfleet serve --ros2 --ros2-network` in one, the Fast DDS peer
(tests/fastdds_peer, Humble's rmw_fastrtps_cpp defaults: every interface, multicast discovery)
in the other, started before and after armfleet. Nothing is sent on the real machine's
interfaces. Without `--ros2-network`, armfleet's DDS stays on its host's loopback: the other
host never sees it and the veth counts no packet sent by its side.
Needs root and `ip` (iproute2); skipped with the reason otherwise.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import ELBOW, JOINTS, ROOT, wait_for
from tests.fastdds_peer import FastDdsPeer, built_or_skip

ADDRESSES = ("10.217.17.1", "10.217.17.2")
PORT = 8000  # a namespace of our own: every port is free


class Hosts:
    """Two namespaces, 'armfleet' and 'ros', joined by a veth pair."""

    def __init__(self) -> None:
        tag = f"{os.getpid() % 10000}{random.randrange(100)}"
        self.ns = {"armfleet": f"af17-{tag}-a", "ros": f"af17-{tag}-r"}
        self.dev = {"armfleet": f"af{tag}a", "ros": f"af{tag}r"}

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
            _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", dev)  # as a default route would

    def down(self) -> None:
        for ns in self.ns.values():
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)

    def run(self, host: str, *cmd: str) -> list[str]:
        return ["ip", "netns", "exec", self.ns[host], *cmd]

    def sent_packets(self) -> int:
        """Packets armfleet's host has sent over the veth."""
        out = subprocess.run(
            ["ip", "-n", self.ns["armfleet"], "-j", "-s", "link", "show", self.dev["armfleet"]],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        return int(json.loads(out)[0]["stats64"]["tx"]["packets"])

    def get(self, path: str) -> Any:
        """GET on armfleet's HTTP port, from inside its host."""
        cmd = self.run(
            "armfleet", "curl", "-sf", "--max-time", "5", f"http://127.0.0.1:{PORT}{path}"
        )
        done = subprocess.run(cmd, capture_output=True, text=True)
        return json.loads(done.stdout) if done.returncode == 0 else None


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@pytest.fixture(scope="module")
def peer_binary() -> Path:
    return built_or_skip()


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
def armfleet(hosts: Hosts, log_dir: Path, *flags: str) -> Iterator[subprocess.Popen[bytes]]:
    """`armfleet serve --ros2 FLAGS` on the armfleet host, until /readyz answers there."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("ROS_LOCALHOST_ONLY", "ROS_AUTOMATIC_DISCOVERY_RANGE", "CYCLONEDDS_URI")
    }
    env.update(PYTHONPATH=str(ROOT), ARMFLEET_DATA_DIR=str(log_dir / "data"), ROS_DOMAIN_ID="17")
    cmd = [sys.executable, "-m", "service.cli", "serve", "--worlds", "2", "--port", str(PORT)]
    cmd += ["--host", "127.0.0.1", "--ros2", "--ros2-rate", "30", *flags]
    with open(log_dir / f"server{'-'.join(flags)}.log", "ab") as log:
        proc = subprocess.Popen(hosts.run("armfleet", *cmd), stdout=log, stderr=log, env=env)
    try:
        wait_for(lambda: proc.poll() is not None or hosts.get("/readyz"), "armfleet", 60)
        assert proc.poll() is None, (log_dir / f"server{'-'.join(flags)}.log").read_text()
        yield proc
    finally:
        proc.kill()  # its orderly shutdown is tested elsewhere; here it would only cost seconds
        proc.wait()


def ros_peer(binary: Path, hosts: Hosts) -> FastDdsPeer:
    return FastDdsPeer(binary, "humble", {"ROS_DOMAIN_ID": "17"}, prefix=hosts.run("ros"))


def test_loopback_default_stays_on_its_host(
    peer_binary: Path, hosts: Hosts, tmp_path: Path
) -> None:
    peer = ros_peer(peer_binary, hosts)
    try:
        before = hosts.sent_packets()
        with armfleet(hosts, tmp_path):
            assert peer.matched("/joint_states", timeout=3)["count"] == 0
            assert peer.matched("/joint_commands", timeout=1)["count"] == 0
            assert hosts.sent_packets() == before  # not one packet on the wire
    finally:
        peer.close()


@pytest.fixture(scope="module")
def early_peer(peer_binary: Path, hosts: Hosts) -> Iterator[FastDdsPeer]:
    peer = ros_peer(peer_binary, hosts)
    yield peer
    peer.close()


@pytest.fixture(scope="module")
def networked(
    early_peer: FastDdsPeer, hosts: Hosts, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[None]:
    with armfleet(hosts, tmp_path_factory.mktemp("netns"), "--ros2-network"):
        yield


def seed_workflow(peer: FastDdsPeer, hosts: Hosts, elbow: float) -> None:
    """Found; commands land exactly (read back over HTTP on armfleet's host); states arrive."""
    for topic in ("/joint_commands", "/joint_states", "/clock"):
        assert peer.matched(topic, timeout=15)["count"] >= 1, f"{topic} not found across hosts"
    wanted = [0.1, -1.2, elbow, -1.5, -1.6, 0.2, 0.3]
    deadline = time.monotonic() + 15
    while hosts.get("/v1/worlds/0/state")["target"] != wanted:  # resent: see test_fastdds
        assert time.monotonic() < deadline, f"world 0's target never became {wanted}"
        peer.publish("/joint_commands", JOINTS, wanted)
        time.sleep(0.5)

    def moved() -> Any:
        state = peer.latest("/joint_states")
        return state if state and abs(state["position"][ELBOW] - elbow) < 0.05 else None

    wait_for(moved, f"/joint_states across hosts to show the elbow at {elbow}", timeout=20)
    first = wait_for(lambda: peer.latest("/clock"), "/clock across hosts")
    wait_for(lambda: peer.latest("/clock")["stamp"] > first["stamp"], "/clock to advance")


def test_node_started_first_on_the_other_host(
    early_peer: FastDdsPeer, networked: None, hosts: Hosts
) -> None:
    seed_workflow(early_peer, hosts, elbow=1.3)
    assert hosts.sent_packets() > 0  # the counter that stays still without --ros2-network


def test_node_started_later_on_the_other_host(
    peer_binary: Path, networked: None, hosts: Hosts
) -> None:
    peer = ros_peer(peer_binary, hosts)
    try:
        seed_workflow(peer, hosts, elbow=0.9)
    finally:
        peer.close()
