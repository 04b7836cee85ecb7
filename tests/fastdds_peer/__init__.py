"""The Fast DDS peer (peer.cpp): built once per source hash, driven over its stdin/stdout.

It is a ROS 2 node as rmw_fastrtps_cpp sets itself up (see peer.cpp), the judge of Fast DDS
compatibility in tests/test_fastdds.py and bench section 8. Building needs Debian's
`libfastrtps-dev`, `fastddsgen` and `g++` (scripts/dev.py installs them for `test`); the binary
goes to `build/fastdds_peer/<hash>/` (ignored by git) and is reused while the sources and the
compiler stay the same. `python -m tests.fastdds_peer` builds it and prints its path.
"""

from __future__ import annotations

import hashlib
import json
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SOURCES = (HERE / "peer.cpp", HERE / "ros2_types.idl")
HEADER = Path("/usr/include/fastdds/dds/domain/DomainParticipant.hpp")
DEBS = "libfastrtps-dev fastddsgen g++"


class PeerUnavailable(RuntimeError):
    """The peer cannot be built here; the text says what is missing."""


def build(root: Path = ROOT, say: Any = None) -> Path:
    """The peer's binary, compiled now only if no build of these sources exists yet."""
    missing = [t for t in ("fastddsgen", "g++") if shutil.which(t) is None]
    if not HEADER.exists():
        missing.append(str(HEADER))
    if missing:
        raise PeerUnavailable(
            f"Fast DDS peer not built: {', '.join(missing)} missing "
            f"(apt-get install {DEBS}; scripts/dev.py test does it)"
        )
    compiler = subprocess.run(["g++", "--version"], capture_output=True, text=True).stdout
    digest = hashlib.sha256(compiler.encode())
    for src in SOURCES:
        digest.update(src.read_bytes())
    out = root / "build" / "fastdds_peer" / digest.hexdigest()[:16]
    binary = out / "fastdds_peer"
    if binary.exists():
        return binary
    if say:
        say("building the Fast DDS test peer (fastddsgen + g++, once per source change)")
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        gen = Path(tmp)
        _run(["fastddsgen", "-replace", "-d", str(gen), str(HERE / "ros2_types.idl")], gen)
        units = [HERE / "peer.cpp", gen / "ros2_types.cxx", gen / "ros2_typesPubSubTypes.cxx"]
        cmd = ["g++", "-std=c++17", "-O1", "-I", str(gen), "-o", str(gen / "fastdds_peer")]
        _run([*cmd, *map(str, units), "-lfastrtps", "-lfastcdr"], gen)
        out.mkdir(exist_ok=True)
        os.replace(gen / "fastdds_peer", binary)  # atomic: a parallel build just wins or loses
    return binary


def built_or_skip() -> Path:
    """For test fixtures: the binary, or the test skipped naming what is missing."""
    import pytest

    try:
        return build()
    except PeerUnavailable as exc:
        pytest.skip(str(exc))


def _run(cmd: list[str], cwd: Path) -> None:
    done = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if done.returncode:
        raise PeerUnavailable(f"{cmd[0]} failed ({done.returncode}):\n{done.stderr[-3000:]}")


class FastDdsPeer:
    """One peer process: `ask` sends a request line and returns its reply's result; samples of
    streamed topics are queued for `sample`.

    distro: 'humble' or 'jazzy' (how the peer reads ROS_LOCALHOST_ONLY and friends)
    env: the ROS variables for the peer (ROS_DOMAIN_ID, ROS_LOCALHOST_ONLY, ...)
    prefix: a command to run it under, e.g. ("ip", "netns", "exec", "ns1")
    """

    def __init__(
        self,
        binary: Path,
        distro: str = "humble",
        env: Mapping[str, str] | None = None,
        prefix: Sequence[str] = (),
        ready_timeout: float = 20.0,
    ) -> None:
        clean = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "CYCLONE"))}
        self.started = time.monotonic()
        self.proc = subprocess.Popen(
            [*prefix, str(binary), distro],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env={**clean, **(env or {})},
        )
        self._replies: queue.Queue[dict[str, Any]] = queue.Queue()
        self._samples: dict[str, queue.Queue[dict[str, Any]]] = {}
        threading.Thread(target=self._read, daemon=True).start()
        ready = self._replies.get(timeout=ready_timeout)
        assert ready.get("ready"), ready
        self.scope: str = ready["scope"]

    def _read(self) -> None:
        assert self.proc.stdout
        for line in self.proc.stdout:
            msg = json.loads(line)
            if msg.get("event") == "sample":
                self._samples.setdefault(msg["topic"], queue.Queue()).put(msg)
            else:
                self._replies.put(msg)
        self._replies.put({"ok": False, "error": f"peer exited ({self.proc.wait()})"})

    def ask(self, line: str, timeout: float = 60.0) -> Any:
        assert self.proc.stdin
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        reply = self._replies.get(timeout=timeout)
        if not reply.get("ok"):
            raise RuntimeError(f"peer: {line!r} -> {reply.get('error')}")
        return reply["result"]

    def publish(self, topic: str, names: Sequence[str], positions: Sequence[float]) -> None:
        nm = ",".join(names) or "-"
        assert self.ask(f"publish {topic} {nm} {','.join(repr(float(p)) for p in positions)}")

    def trajectory(
        self, topic: str, names: Sequence[str], positions: Sequence[float], seconds: float
    ) -> None:
        """Publish a one-point trajectory_msgs/JointTrajectory reaching `positions` at `seconds`."""
        values = ",".join(repr(float(p)) for p in positions)
        assert self.ask(f"trajectory {topic} {','.join(names)} {values} {seconds!r}")

    def matched(self, topic: str, timeout: float = 20.0) -> dict[str, Any]:
        """{'count': matched endpoints (0: none in time), 'ms': from start to the first match}"""
        return self.ask(f"matched {topic} {timeout}", timeout + 10)

    def latest(self, topic: str) -> dict[str, Any] | None:
        return self.ask(f"latest {topic}")

    def stream(self, topic: str) -> None:
        self._samples.setdefault(topic, queue.Queue())
        assert self.ask(f"stream {topic}")

    def sample(self, topic: str, timeout: float) -> dict[str, Any] | None:
        """The next streamed sample: {'t': CLOCK_MONOTONIC receive time, 'msg': {...}}."""
        try:
            return self._samples[topic].get(timeout=timeout)
        except queue.Empty:
            return None

    def discovery(self, timeout: float = 10.0) -> dict[str, Any]:
        return self.ask(f"discovery {timeout}", timeout + 10)

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin
                self.proc.stdin.write("quit\n")
                self.proc.stdin.flush()
                self.proc.wait(timeout=10)  # deleting the participant frees its /dev/shm segment
            except (OSError, subprocess.TimeoutExpired) as exc:
                print(f"fastdds peer killed ({type(exc).__name__})", file=sys.stderr)
                self.proc.kill()
                self.proc.wait()
