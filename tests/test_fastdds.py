"""ROS 2 Humble's default middleware finds armfleet on one machine, whichever starts first.

The judge is a real Fast DDS participant (tests/fastdds_peer: Debian's Fast DDS 2.9, types from
fastddsgen) set up the way rmw_fastrtps_cpp sets itself up: multicast discovery only, no initial
peers. One `armfleet serve --ros2` is shared: a peer started before it, peers started after it
(Humble with and without ROS_LOCALHOST_ONLY=1, Jazzy's LOCALHOST range) and one restarted ten
times. Each drives the seed's workflow over real sockets on loopback: a JointState on
/joint_commands becomes world 0's target exactly (read back over HTTP), /joint_states and /clock
(rclcpp's ClockQoS) arrive, /world_N topics reach their world, and ros_discovery_info names node
/armfleet with its endpoints.
"""

from __future__ import annotations

import random
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from service.surfaces.ros import topics
from tests.conftest import ELBOW, FINGER, JOINTS, Server, node_armfleet, serve, wait_for
from tests.fastdds_peer import FastDdsPeer, built_or_skip

COMMANDS = ("/joint_commands", "/world_1/joint_commands")
STATES = ("/joint_states", "/world_1/joint_states", "/clock")
LOCALHOST_ONLY = {"ROS_LOCALHOST_ONLY": "1"}


@pytest.fixture(scope="module")
def peer_binary() -> Path:
    return built_or_skip()


@pytest.fixture(scope="module")
def domain() -> int:
    """A DDS domain of its own (a parallel run or a developer's server is not heard)."""
    return random.SystemRandom().randrange(1, 233)


@pytest.fixture(scope="module")
def early_peer(peer_binary: Path, domain: int) -> Iterator[FastDdsPeer]:
    """A Humble node with ROS_LOCALHOST_ONLY=1, running before armfleet starts."""
    peer = FastDdsPeer(peer_binary, "humble", {"ROS_DOMAIN_ID": str(domain), **LOCALHOST_ONLY})
    yield peer
    peer.close()


@pytest.fixture(scope="module")
def ros_server(
    early_peer: FastDdsPeer, tmp_path_factory: pytest.TempPathFactory, domain: int
) -> Iterator[Server]:
    extra = ("--ros2", "--ros2-worlds", "1", "--ros2-rate", "30")
    env = {"ROS_DOMAIN_ID": str(domain)}
    with serve(
        worlds=2, extra_args=extra, env=env, log_dir=tmp_path_factory.mktemp("fastdds")
    ) as s:
        yield s


def late_peer(binary: Path, domain: int, distro: str, env: dict[str, str]) -> FastDdsPeer:
    return FastDdsPeer(binary, distro, {"ROS_DOMAIN_ID": str(domain), **env})


def _target(server: Server, world: int) -> list[float]:
    return httpx.get(f"{server.url}/v1/worlds/{world}/state").json()["target"]


def assert_discovers(peer: FastDdsPeer, topics_: tuple[str, ...] = COMMANDS + STATES) -> None:
    for topic in topics_:
        found = peer.matched(topic, timeout=15)
        assert found["count"] >= 1, f"{peer.scope}: armfleet's endpoint on {topic} not found"


def assert_command_lands(peer: FastDdsPeer, server: Server, wanted: list[float]) -> int:
    """The seed's message (all seven names and positions) becomes world 0's target exactly.

    The peer's writer matching armfleet's reader does not mean armfleet's reader has matched
    the writer yet; a volatile sample written in between is lost (in any DDS, as with rclpy's
    first publish right after start), so the message is sent again each second until it lands.
    Returns how many sends it took."""
    sends = 0
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        peer.publish("/joint_commands", JOINTS, wanted)
        sends += 1
        resend = time.monotonic() + 1.0
        while time.monotonic() < resend:
            if _target(server, 0) == wanted:
                return sends
            time.sleep(0.02)
    raise AssertionError(f"{peer.scope}: world 0's target never became {wanted} ({sends} sends)")


def assert_seed_workflow(peer: FastDdsPeer, server: Server, elbow: float) -> None:
    wanted = [0.1, -1.2, elbow, -1.5, -1.6, 0.2, 0.3]
    assert_command_lands(peer, server, wanted)

    def moved() -> Any:
        state = peer.latest("/joint_states")
        return state if state and abs(state["position"][ELBOW] - elbow) < 0.05 else None

    state = wait_for(moved, f"/joint_states to show the elbow at {elbow} rad", timeout=20)
    assert state["name"] == JOINTS and len(state["velocity"]) == len(state["effort"]) == 7
    assert state["stamp"] != [0, 0]  # simulated time

    first = wait_for(lambda: peer.latest("/clock"), "/clock (best effort, keep last 1)")
    wait_for(lambda: peer.latest("/clock")["stamp"] > first["stamp"], "/clock to advance")

    before = _target(server, 1)
    peer.publish("/world_1/joint_commands", ["finger_joint"], [0.25 + elbow / 100])
    wait_for(lambda: _target(server, 1)[FINGER] == 0.25 + elbow / 100, "world 1's finger")
    assert _target(server, 1)[:FINGER] == before[:FINGER]
    wait_for(
        lambda: (s := peer.latest("/world_1/joint_states")) and s["position"][FINGER] > 0.05,
        "/world_1/joint_states to show the finger closing",
        timeout=20,
    )


def test_node_started_before_armfleet_finds_it(early_peer: FastDdsPeer, ros_server: Server) -> None:
    assert_discovers(early_peer)
    assert_seed_workflow(early_peer, ros_server, elbow=1.3)


@pytest.mark.parametrize(
    ("distro", "env"),
    [
        ("humble", LOCALHOST_ONLY),
        ("humble", {}),  # Fast DDS defaults: every interface, multicast discovery
        ("jazzy", {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}),
    ],
    ids=["humble-localhost-only", "humble-defaults", "jazzy-localhost"],
)
def test_node_started_after_armfleet_finds_it(
    peer_binary: Path, domain: int, ros_server: Server, distro: str, env: dict[str, str]
) -> None:
    peer = late_peer(peer_binary, domain, distro, env)
    try:
        assert_discovers(peer)
        if env == LOCALHOST_ONLY:
            assert_seed_workflow(peer, ros_server, elbow=1.1)
        else:
            assert_command_lands(peer, ros_server, [0.2, -1.0, 0.9, -1.4, -1.5, 0.1, 0.4])
    finally:
        peer.close()


def test_a_node_restarted_ten_times_is_found_every_time(
    peer_binary: Path, domain: int, ros_server: Server
) -> None:
    sends = []
    for i in range(10):
        peer = late_peer(peer_binary, domain, "humble", LOCALHOST_ONLY)
        try:
            assert_discovers(peer, ("/joint_commands", "/joint_states"))
            wanted = [0.01 * i, -1.0, 1.0, -1.5, -1.5, 0.0, 0.0]
            sends.append(assert_command_lands(peer, ros_server, wanted))
        finally:
            peer.close()
    print("sends needed per restart:", sends)


def test_clock_is_simulated_time_exactly(early_peer: FastDdsPeer, ros_server: Server) -> None:
    tick_dt = 1.0 / httpx.get(f"{ros_server.url}/v1/info").json()["control_hz"]
    httpx.post(f"{ros_server.url}/v1/sim/pause").raise_for_status()
    try:
        tick = httpx.get(f"{ros_server.url}/v1/worlds/0/state").json()["tick"]
        httpx.post(f"{ros_server.url}/v1/sim/step", json={"ticks": 30}, timeout=30)
        stamp = list(topics.stamp((tick + 30) * tick_dt))
        wait_for(lambda: early_peer.latest("/clock")["stamp"] == stamp, f"/clock at {stamp}")
    finally:
        httpx.post(f"{ros_server.url}/v1/sim/resume").raise_for_status()


def test_ros_discovery_info_names_node_armfleet(
    early_peer: FastDdsPeer, ros_server: Server
) -> None:
    """What `ros2 node list` and `ros2 topic info -v` read: node /armfleet owning exactly the
    readers and writers Fast DDS's own discovery reports on its topics."""
    assert_discovers(early_peer)
    seen = early_peer.discovery()
    owned = {
        "rt/joint_states": "writers",
        "rt/world_1/joint_states": "writers",
        "rt/clock": "writers",
        "rt/joint_commands": "readers",
        "rt/world_1/joint_commands": "readers",
    }
    node = node_armfleet(seen, owned)
    for kind in ("writers", "readers"):  # and every endpoint it names is one DDS reported
        discovered = {g + "00" * 8 for guids in seen[kind].values() for g in guids}
        assert set(node[kind]) <= discovered, kind


def test_a_joint_trajectory_from_fast_dds_runs(early_peer: FastDdsPeer, ros_server: Server) -> None:
    """A controller's `~/joint_trajectory` topic (trajectory_msgs/JointTrajectory, fire and
    forget) from a Fast DDS node: world 1 follows it to its last point."""
    topic = "/world_1/scaled_joint_trajectory_controller/joint_trajectory"
    assert early_peer.matched(topic, timeout=15)["count"] >= 1
    wanted = [0.35, -1.3, 1.45, -1.7, -1.5, 0.25]
    deadline = time.monotonic() + 15
    while _target(ros_server, 1)[:6] != wanted and time.monotonic() < deadline:
        # resent until armfleet's reader has matched this writer too (see assert_command_lands)
        early_peer.trajectory(topic, JOINTS[:6], wanted, 0.5)
        wait_until = time.monotonic() + 2.0
        while _target(ros_server, 1)[:6] != wanted and time.monotonic() < wait_until:
            time.sleep(0.05)
    assert _target(ros_server, 1)[:6] == wanted
