"""The line protocol between a test and a peer process (tests/ros2_peer.py, ros2_ur_peer.py).

The peers run in processes of their own so that their DDS participants are separate from
everything in the test process; the test sends one JSON request per line and reads one JSON
reply per line.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def serve_lines(handle: Callable[[dict], object]) -> None:
    """Peer side: answer each stdin line until stdin closes; an exception becomes an error."""
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        try:
            reply = {"ok": True, "result": handle(json.loads(line))}
        except Exception as exc:
            reply = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        print(json.dumps(reply), flush=True)


class PeerProcess:
    """Test side: start `python -m <module>` with the given environment; ask it things."""

    def __init__(self, module: str, env: dict[str, str]) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", module],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env={**os.environ, **env, "PYTHONPATH": str(ROOT)},
            cwd=ROOT,
        )
        assert json.loads(self.proc.stdout.readline()) == {"ready": True}  # type: ignore[union-attr]

    def ask(self, **req: Any) -> Any:
        assert self.proc.stdin and self.proc.stdout
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        reply = json.loads(self.proc.stdout.readline())
        assert reply["ok"], reply
        return reply["result"]

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()


class UrPeer(PeerProcess):
    """tests/ros2_ur_peer.py in its own process, on DDS domain `domain` over loopback."""

    def __init__(self, domain: int) -> None:
        from service.surfaces.ros.dds import LOOPBACK_CONFIG

        env = {"CYCLONEDDS_URI": LOOPBACK_CONFIG, "ROS_DOMAIN_ID": str(domain)}
        super().__init__("tests.ros2_ur_peer", env)

    def call(self, action: str, kind: str, service: str, request: dict, timeout: float = 15) -> Any:
        """Call one of an action's services the rmw_cyclonedds way; the decoded reply."""
        suffix = {"send_goal": "SendGoal", "get_result": "GetResult"}.get(service)
        ros_type = f"{kind}_{suffix}" if suffix else "action_msgs/srv/CancelGoal"
        reply = self.ask(
            op="call",
            service=f"{action}/_action/{service}",
            type=ros_type,
            request=request,
            timeout=timeout,
        )
        assert reply is not None, f"no reply from {action} {service}"
        return reply
