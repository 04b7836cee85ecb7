"""`--ros2`: the armfleet_ros node as a supervised child process on the user's ROS 2.

The node (packaging/armfleet-ros) runs on the ROS installation's Python, found and prepared by
node_env.py when the service is built (a missing ROS is one line at start, not a crash later).
Once the loop runs it is started with the service's URL, `--ros2-worlds`, `--ros2-rate`,
`--ros2-cameras` and `--camera-rate` as ROS parameters, and the administrator's `--token` (if
any) in its environment as ARMFLEET_TOKEN (never on its command line, which `ps` shows to
everyone, and never logged). It runs in a process group of its own (a terminal's Ctrl-C reaches
armfleet, which stops the node itself: SIGINT to its group, SIGKILL after 10 s), and is killed
with armfleet if armfleet dies (PR_SET_PDEATHSIG). If it exits on its own it is started again
after a backoff (1 s, doubling to 10 s while it keeps failing within 30 s); while it is down
`/readyz` names the problem, and the restarts are logged and counted in `GET /v1/ros`.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import subprocess
import threading
import time
from typing import Any

from service.core.surface import ServiceFacts, SurfaceContext
from service.surfaces.ros.node_env import NodeEnv, node_env
from service.surfaces.ros.settings import Ros2Settings

log = logging.getLogger("armfleet.ros")

STOP_TIMEOUT_S = 10.0
TOKEN_ENV = "ARMFLEET_TOKEN"  # what armfleet_ros/auth.py reads
_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when armfleet goes (Linux; elsewhere nothing)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


class RosNode:
    """The supervised armfleet_ros process."""

    name = "ros2"

    def __init__(
        self, settings: Ros2Settings, facts: ServiceFacts, prepared: NodeEnv | None = None
    ) -> None:
        self.settings, self.facts = settings, facts
        self.node = prepared or node_env(settings.python)
        self.process: subprocess.Popen[bytes] | None = None
        self.restarts = 0
        self.last_exit: int | None = None
        self.started_at: float | None = None
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None

    def command(self) -> list[str]:
        s, facts = self.settings, self.facts
        params = [f"url:={facts.url}", f"worlds:={s.worlds}", f"rate:={float(s.rate)}"]
        cameras = ",".join(c.strip() for c in s.cameras.split(",") if c.strip())
        if cameras:
            params += [f"cameras:={cameras}", f"camera_rate:={float(facts.camera_rate)}"]
        args = [self.node.python, "-m", "armfleet_ros.node", "--ros-args"]
        for p in params:
            args += ["-p", p]
        return args

    def start(self, ctx: SurfaceContext) -> None:
        # Every spawn happens on the watch thread: PR_SET_PDEATHSIG fires when the *thread*
        # that started the child ends, and this one lives as long as the supervision.
        self._thread = threading.Thread(target=self._watch, name="armfleet-ros-node", daemon=True)
        self._thread.start()

    def child_env(self) -> dict[str, str]:
        """The node's environment: the ROS one, and the token it presents (or none at all)."""
        env = dict(self.node.env)
        env.pop(TOKEN_ENV, None)
        if self.facts.access.token:
            env[TOKEN_ENV] = self.facts.access.token
        return env

    def _spawn(self) -> None:
        self.process = subprocess.Popen(
            self.command(),
            env=self.child_env(),
            start_new_session=True,
            preexec_fn=_die_with_parent,
        )
        self.started_at = time.monotonic()
        log.info("ROS 2 node started (pid %d, %s)", self.process.pid, self.node.python)

    def _watch(self) -> None:
        self._spawn()
        delay = 0.5
        while not self._stopping.is_set():
            assert self.process is not None
            code = self.process.wait()
            if self._stopping.is_set():
                return
            self.last_exit = code
            ran = time.monotonic() - (self.started_at or 0.0)
            delay = 1.0 if ran > 30 else min(10.0, delay * 2)
            log.warning(
                "ROS 2 node exited with status %s after %.1f s; restarting in %.0f s",
                code,
                ran,
                delay,
            )
            if self._stopping.wait(delay):
                return
            self.restarts += 1
            self._spawn()

    def problems(self) -> list[str]:
        """For /readyz: the node is down (between an exit and its restart)."""
        p = self.process
        if p is None or self._stopping.is_set() or p.poll() is None:
            return []
        return [
            f"ROS 2 node exited with status {p.returncode}; restarting (restarts {self.restarts})"
        ]

    def status(self) -> dict[str, Any]:
        p = self.process
        return {
            "enabled": True,
            "python": self.node.python,
            "pid": None if p is None else p.pid,
            "running": p is not None and p.poll() is None,
            "restarts": self.restarts,
            "last_exit": self.last_exit,
        }

    def stop(self) -> None:
        self._stopping.set()
        p = self.process
        if p is None or p.poll() is not None:
            return
        try:
            os.killpg(p.pid, signal.SIGINT)
            p.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            log.warning("ROS 2 node did not stop in %.0f s: killed", STOP_TIMEOUT_S)
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        except ProcessLookupError:
            pass
        if self._thread is not None:
            self._thread.join(timeout=2)
