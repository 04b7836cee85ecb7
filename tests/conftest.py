"""Shared fixtures: a real `armfleet serve` process on a free loopback port.

End-to-end tests talk to it over real sockets; nothing of the engine or server is mocked.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest

from clients import ArmfleetClient, WorldState

ROOT = Path(__file__).resolve().parents[1]

# The commanded joints and the `home` keyframe, as the tests expect the service to publish them.
JOINTS = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
    "finger_joint",
]
HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0, 0.0]
ELBOW, FINGER = 2, 6


def wait_for(pred: Callable[[], Any], what: str, timeout: float = 15) -> Any:
    """Poll `pred` until it returns something truthy; fail naming `what` after `timeout` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = pred()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.05)


def target_after(client: ArmfleetClient, world: int, pred: Callable[[WorldState], bool]) -> Any:
    """The world's targets once `pred(state)` holds (commands apply at the next tick)."""

    def check() -> WorldState | None:
        state = client.state(world)
        return state if pred(state) else None

    return wait_for(check, f"world {world}'s target to change").target


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Server:
    url: str
    ws_url: str
    process: subprocess.Popen[bytes]
    log_path: Path

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")


@contextlib.contextmanager
def running_server(
    tmp_path: Path,
    worlds: int = 4,
    mode: str = "realtime",
    port: int | None = None,
    extra: tuple[str, ...] = (),
) -> Iterator[Server]:
    """Start `armfleet serve` and wait for /readyz; stop it (SIGINT, like Ctrl-C) afterwards."""
    port = port or free_port()
    log_path = tmp_path / f"server-{port}.log"
    cmd = [sys.executable, "-m", "service.cli", "serve", "--worlds", str(worlds)]
    cmd += ["--port", str(port), "--mode", mode, *extra]
    with open(log_path, "ab") as log:
        env = os.environ.copy()
        # Snapshots (`latest` on every stop) and recordings stay with the test, not in ~/.local.
        env.setdefault("ARMFLEET_DATA_DIR", str(tmp_path / "data"))
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, env=env)
    url = f"http://127.0.0.1:{port}"
    server = Server(url=url, ws_url=f"ws://127.0.0.1:{port}", process=proc, log_path=log_path)
    try:
        deadline = time.monotonic() + 300  # a cold kernel cache compiles for a while
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"server exited with {proc.returncode}:\n{server.log()}")
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{url}/readyz", timeout=1).status_code == 200:
                    break
            if time.monotonic() > deadline:
                raise RuntimeError(f"server not ready in time:\n{server.log()}")
            time.sleep(0.2)
        yield server
    finally:
        proc.send_signal(2)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """A 4-world realtime server shared by the tests of one module."""
    with running_server(tmp_path_factory.mktemp("server")) as srv:
        yield srv
