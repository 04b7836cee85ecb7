"""`armfleet serve --ros2 --token T --leases optional`: the node presents the administrator's
token (handed to it in its environment, never on a command line) on every HTTP request and
WebSocket handshake, so the seed's JointState command moves the arm, a leased world included,
while the same command over HTTP without the token is refused. The token appears in neither
armfleet's log nor the node's (which writes into the same file). Judged by the real rclpy of
tests/ros2_judge.py.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest

from tests import ros2_judge
from tests.conftest import JOINTS, serve, wait_for
from tests.test_ros_node import judge, node_report, server_env, targets

pytestmark = pytest.mark.skipif(
    ros2_judge.skip_reason() is not None, reason=str(ros2_judge.skip_reason())
)

TOKEN = "tok-" + "7q" * 16  # something no log line would hold by chance
GRAPH = 60  # a ROS domain of its own (offset from this process's)


def test_node_presents_the_token_and_commands_leased_worlds(tmp_path: Any) -> None:
    args = ["--engine", "mujoco", "--ros2", "--ros2-worlds", "1", "--token", TOKEN]
    args += ["--leases", "optional", "--ros2-python", ros2_judge.python()]
    admin = {"Authorization": f"Bearer {TOKEN}"}
    with (
        serve(worlds=2, extra_args=args, env=server_env(GRAPH), log_dir=tmp_path) as srv,
        httpx.Client(base_url=srv.url, timeout=10) as http,
    ):
        node = node_report(http)
        cmdline = Path(f"/proc/{node['pid']}/cmdline").read_bytes()
        assert TOKEN.encode() not in cmdline  # not on the node's command line
        # someone holds world 1: only its lease and the administrator command it
        lease = http.post("/v1/leases", json={"worlds": [1], "label": "ros"}, headers=admin)
        assert lease.status_code == 201, lease.text
        before = targets(http, 0)
        body = {"name": ["elbow_joint"], "position": [0.9]}
        refused = http.put("/v1/worlds/0/targets", json=body)
        assert refused.status_code == 401, refused.text
        assert targets(http, 0) == before  # the token matters, and nothing changed
        for ns, world, value in (("", 0, 0.35), ("/world_1", 1, 0.4)):
            seen = judge("seed", ns, str(value), domain=GRAPH)
            assert seen["reached"] and seen["name"] == JOINTS
            assert targets(http, world) == [0.0, -1.4, 1.5, -1.57, -1.57, 0.0, value]

        def accepted() -> int | None:
            n = http.get("/v1/ros").json()["node"]["report"]["accepted"]
            return n if n >= 2 else None

        wait_for(accepted, "the node's report of both commands", 30)
    log = srv.log_path.read_text()
    assert "ROS 2 node started" in log and "connected to armfleet" in log  # the node's log too
    assert TOKEN not in log
