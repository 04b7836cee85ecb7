"""`armfleet watch` against a real server: JSON lines for piping, and the live table."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import pty
import queue
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from conftest import JOINTS, ROOT, Server

from clients import ArmfleetClient

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")  # colours and cursor moves of a terminal


def watch(url: str, *args: str) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "service.cli", "watch", "--url", url, *args]
    return subprocess.Popen(
        cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


class Lines:
    """Lines of a process's stdout as they come (a reader thread), with timeouts."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self._q: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self._q.put(line)

    def next(self, timeout: float = 15) -> str:
        return self._q.get(timeout=timeout)


@pytest.fixture
def json_watch(server: Server) -> Iterator[Lines]:
    proc = watch(server.url, "--world", "1", "--rate", "20", "--json")
    try:
        yield Lines(proc)
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_json_mode_prints_one_state_per_line_with_increasing_ticks(json_watch: Lines) -> None:
    frames: list[dict[str, Any]] = [json.loads(json_watch.next()) for _ in range(6)]
    ticks = [f["tick"] for f in frames]
    assert ticks == sorted(ticks) and len(set(ticks)) == len(ticks)
    for frame in frames:
        assert frame["world"] == 1
        assert frame["name"] == JOINTS
        assert len(frame["position"]) == 7 and len(frame["target"]) == 7
        assert len(frame["flange"]["quaternion"]) == 4


def test_json_lines_show_a_target_set_through_the_api(server: Server, json_watch: Lines) -> None:
    json.loads(json_watch.next())  # streaming
    with ArmfleetClient(server.url) as client:
        ack = client.set_targets(1, {"elbow_joint": 1.0})
        try:
            deadline = time.monotonic() + 10
            while True:
                frame = json.loads(json_watch.next())
                if frame["tick"] >= ack.tick:
                    break
                assert time.monotonic() < deadline, "no frame at or after the command's tick"
            assert frame["target"][2] == pytest.approx(1.0)
        finally:
            client.reset(1)


def test_table_mode_shows_the_joint_rows(server: Server) -> None:
    """The live table in a terminal (a pty, so Rich redraws as it would for a user); Ctrl-C
    once it shows a frame ends it cleanly."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 160, 0, 0))
    # The CLI as `python -m service.cli` in a terminal's foreground job: SIGINT raises
    # KeyboardInterrupt even when this suite runs as a background job (`cmd &` starts it with
    # SIGINT ignored, and a child inherits that). Every thread's stack goes to stderr on
    # SIGUSR1, so a failure to stop says where it was.
    boot = (
        "import faulthandler, runpy, signal, sys; "
        "signal.signal(signal.SIGINT, signal.default_int_handler); "
        "faulthandler.register(signal.SIGUSR1, all_threads=True); "
        "sys.argv[0] = 'armfleet'; runpy.run_module('service.cli', run_name='__main__')"
    )
    cmd = [sys.executable, "-c", boot, "watch", "--url", server.url]
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "160", "LINES": "40"}
    proc = subprocess.Popen(
        [*cmd, "--world", "0", "--rate", "10"],
        cwd=ROOT,
        env=env,
        stdin=slave,
        stdout=slave,
        stderr=subprocess.PIPE,
    )
    os.close(slave)
    screen = ""
    try:
        wanted = ["world 0", "tick", "flange", *JOINTS]
        deadline = time.monotonic() + 60
        while not all(w in screen for w in wanted):
            assert time.monotonic() < deadline, f"the table never showed {wanted}: {screen!r}"
            if select.select([master], [], [], 0.5)[0]:
                screen += ANSI.sub("", os.read(master, 65536).decode(errors="replace"))
        proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 20
        while proc.poll() is None and time.monotonic() < deadline:  # keep reading: never block it
            if select.select([master], [], [], 0.2)[0]:
                with contextlib.suppress(OSError):  # EIO once the child has closed the pty
                    os.read(master, 65536)
        if proc.poll() is None:
            with open(f"/proc/{proc.pid}/status") as f:  # blocked, ignored, pending signals
                masks = [
                    line.strip()
                    for line in f
                    if line.startswith(("SigPnd", "ShdPnd", "SigBlk", "SigIgn"))
                ]
            proc.send_signal(signal.SIGUSR1)  # the stacks, then fail with them
            time.sleep(1)
            proc.kill()
            proc.wait()
            raise AssertionError(f"no exit 20 s after Ctrl-C: {masks} {proc.stderr.read()!r}")
        assert proc.wait(timeout=5) == 0, proc.stderr.read() if proc.stderr else ""
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)


def test_unknown_world_exits_with_the_server_detail(server: Server) -> None:
    proc = watch(server.url, "--world", "9", "--json")
    out, err = proc.communicate(timeout=15)
    assert proc.returncode == 1
    assert out == ""
    assert "world 9 does not exist" in err
