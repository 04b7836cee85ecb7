"""Section 8's other DDS nodes: Fast DDS (Humble's default middleware) next to Cyclone.

* Time to first match: a fresh node started after armfleet, from the creation of its DDS
  participant to its `/joint_commands` writer matching armfleet's reader (both discovery
  phases done: the node may publish). Fast DDS is tests/fastdds_peer set up as Humble's
  rmw_fastrtps_cpp with ROS_LOCALHOST_ONLY=1 (multicast discovery only, no initial peers);
  Cyclone is a fresh Python process with a Cyclone participant (`python -m bench.dds_peers
  CONFIG`), once with unicast-only discovery on 127.0.0.1 and once with armfleet's own loopback
  configuration (multicast on lo + unicast). Process start-up is not counted.
* JointState round trip through the Fast DDS node: the same loop as the Cyclone and rosbridge
  clients (ros_bench._round_trips); its receive times are CLOCK_MONOTONIC, as perf_counter is.

The Fast DDS peer is built from the checkout's tests/fastdds_peer (needs libfastrtps-dev and
fastddsgen, as `scripts/dev.py test` installs); without it these rows are reported as errors.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
# A plain Cyclone node on loopback: unicast discovery to 127.0.0.1 only, no multicast.
UNICAST_ONLY = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface address="127.0.0.1"/>'
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery><Peers>"
    '<Peer address="127.0.0.1"/></Peers><ParticipantIndex>auto</ParticipantIndex>'
    "<MaxAutoParticipantIndex>50</MaxAutoParticipantIndex></Discovery></Domain></CycloneDDS>"
)


def peer_module() -> ModuleType:
    """tests/fastdds_peer (build + driver), loaded from the checkout by path."""
    spec = importlib.util.spec_from_file_location(
        "armfleet_fastdds_peer", ROOT / "tests" / "fastdds_peer" / "__init__.py"
    )
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def fastdds_first_matches(domain: int, n: int) -> list[float]:
    """Seconds to first match for `n` fresh Fast DDS nodes, one after another."""
    peers = peer_module()
    binary = peers.build()
    env = {"ROS_DOMAIN_ID": str(domain), "ROS_LOCALHOST_ONLY": "1"}
    out = []
    for _ in range(n):
        peer = peers.FastDdsPeer(binary, "humble", env)
        try:
            found = peer.matched("/joint_commands", timeout=30)
        finally:
            peer.close()
        if not found["count"]:
            raise RuntimeError("a Fast DDS node did not find armfleet in 30 s")
        out.append(found["ms"] / 1e3)
    return out


def cyclone_first_matches(domain: int, n: int, config: str) -> list[float]:
    """Seconds to first match for `n` fresh Cyclone processes with `config`."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "PYTHONPATH": str(ROOT)}
    out = []
    for _ in range(n):
        done = subprocess.run(
            [sys.executable, "-m", "bench.dds_peers", config],
            capture_output=True,
            text=True,
            env=env,
            timeout=60,
        )
        if done.returncode:
            raise RuntimeError(f"Cyclone node: {done.stderr.strip()[-500:]}")
        out.append(json.loads(done.stdout)["seconds"])
    return out


def fastdds_round_trip(
    domain: int, n: int, round_trips: Callable[..., dict[str, Any]], joint: str
) -> dict[str, Any]:
    """`round_trips(send, next_state, n)` through a Fast DDS node (Humble, localhost only)."""
    peers = peer_module()
    env = {"ROS_DOMAIN_ID": str(domain), "ROS_LOCALHOST_ONLY": "1"}
    peer = peers.FastDdsPeer(peers.build(), "humble", env)
    try:
        for topic in ("/joint_commands", "/joint_states"):
            if not peer.matched(topic, timeout=30)["count"]:
                raise RuntimeError(f"Fast DDS node: armfleet's {topic} not found")
        peer.stream("/joint_states")

        def next_state(timeout: float) -> tuple[float, list[float]] | None:
            s = peer.sample("/joint_states", timeout)
            return None if s is None else (s["t"], s["msg"]["position"])

        return round_trips(lambda target: peer.publish("/joint_commands", [joint], [target]),
                           next_state, n)  # fmt: skip
    finally:
        peer.close()


def _cyclone_node(config: str) -> None:
    """Child process: one Cyclone participant; print the seconds to its writer's first match."""
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from service.surfaces.ros import msgs
    from service.surfaces.ros.dds import _qos

    domain = int(os.environ["ROS_DOMAIN_ID"])
    t0 = time.perf_counter()
    dds_domain = Domain(domain, config)  # kept: a collected Domain takes its config along
    dp = DomainParticipant(domain)
    writer = DataWriter(dp, Topic(dp, "rt/joint_commands", msgs.JointState), qos=_qos(10))
    while not writer.get_publication_matched_status().current_count:
        if time.perf_counter() - t0 > 30:
            raise SystemExit("armfleet not found in 30 s")
        time.sleep(0.001)
    print(json.dumps({"seconds": time.perf_counter() - t0}), flush=True)
    del dds_domain
    os._exit(0)  # no orderly DDS teardown needed


if __name__ == "__main__":
    _cyclone_node(sys.argv[1])
