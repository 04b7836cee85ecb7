"""In real time the threads that step the worlds run at a raised priority when the process may
(`--engine-priority auto`, the default), and not with `off`; a server that may not raise it
still serves and says so in its log (service/core/process/engine_priority.py).

What a thread runs at is read from the kernel (/proc/<pid>/task/<tid>/stat), and whether this
process may raise one is asked of the kernel too (a thread of ours tries). The raised case on a
running server is in test_ur_leases.py, on that module's server; here: `off`, a server without
the privilege (root without CAP_SYS_NICE, RLIMIT_NICE 0: the caller's session dropped to an
ordinary user's), and the mode switch on the loop's own object. Native MuJoCo servers.
"""

from __future__ import annotations

import os
import shutil
import sys
import threading
from pathlib import Path

import httpx
import pytest

from service.core.process.engine_priority import (
    COMPANION_STEPS,
    NICEST,
    RAISE_STEPS,
    EnginePriority,
)
from tests.ur_judge import ur_server

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="priority is per thread on Linux only"
)
RAISED_LINE = "engine priority: the threads that step the worlds run at nice"
REFUSED_LINE = "engine priority: not permitted to raise the engine's threads"


def task_nices(pid: int) -> dict[int, int]:
    """Every thread of process `pid`: its nice value, as /proc/<pid>/task/<tid>/stat says
    (field 19; the fields after the command's closing parenthesis start at field 3)."""
    out = {}
    for name in os.listdir(f"/proc/{pid}/task"):
        try:
            text = Path(f"/proc/{pid}/task/{name}/stat").read_text()
        except OSError:  # a thread that ended while we looked
            continue
        out[int(name)] = int(text[text.rindex(")") + 2 :].split()[16])
    return out


def may_raise_to(base: int) -> int | None:
    """The highest priority (lowest nice, at most RAISE_STEPS above `base`) the kernel lets a
    thread of this process take: None when it refuses any step above `base`."""
    found: list[int | None] = [None]

    def attempt() -> None:
        tid = threading.get_native_id()
        for nice in range(max(NICEST, base - RAISE_STEPS), base):
            try:
                os.setpriority(os.PRIO_PROCESS, tid, nice)
            except PermissionError:
                continue
            found[0] = nice
            return

    t = threading.Thread(target=attempt)  # a thread of its own: it ends with what it took
    t.start()
    t.join()
    return found[0]


def _engine(server) -> dict:
    return httpx.get(f"{server.url}/v1/ur").json()["engine_priority"]


def test_off_leaves_every_thread_at_the_process_priority(tmp_path: Path) -> None:
    base = os.getpriority(os.PRIO_PROCESS, 0)  # the server starts with ours
    extra = ("--engine-priority", "off")
    with ur_server(2, tmp_path, extra, mode="realtime") as (server, _):
        engine = _engine(server)
        assert engine["setting"] == "off" and not engine["raised"]
        assert [t["nice"] for t in engine["threads"]] == [base]  # the sim thread, reported
        assert min(task_nices(server.process.pid).values()) == base  # none above it
        assert "engine priority" not in server.log()


@pytest.mark.skipif(
    shutil.which("setpriv") is None, reason="setpriv (util-linux) drops a capability"
)
def test_a_server_that_may_not_raise_serves_at_the_process_priority_and_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Started the way an ordinary user's process is: without CAP_SYS_NICE (dropped from the
    bounding set, so root's exec does not get it back) and with RLIMIT_NICE 0."""
    base = os.getpriority(os.PRIO_PROCESS, 0)
    drop = "setpriv --bounding-set=-sys_nice --inh-caps=-sys_nice -- " if os.geteuid() == 0 else ""
    limit = (
        "import os, resource, sys; resource.setrlimit(resource.RLIMIT_NICE, (0, 0)); "
        "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])"
    )
    python = tmp_path / "python-unprivileged"
    python.write_text(f"#!/bin/sh\nexec {drop}{sys.executable} -c '{limit}' \"$@\"\n")
    python.chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(python))  # what serve() starts the server with
    with ur_server(2, tmp_path, mode="realtime") as (server, _):
        engine = _engine(server)
        assert engine["setting"] == "auto" and engine["permitted"] is False
        assert not engine["raised"] and engine["process_nice"] == base
        assert min(task_nices(server.process.pid).values()) == base
        assert REFUSED_LINE in server.log() and RAISED_LINE not in server.log()
        assert httpx.get(f"{server.url}/readyz").status_code == 200  # and it serves


def test_the_loop_raises_in_real_time_and_puts_back_otherwise() -> None:
    """The sim thread's `follow` at each turn: raised in real time (itself and the engine's
    other stepping thread; a companion, COMPANION_STEPS), back to where they were in fast
    mode, raised again on return."""
    base = os.getpriority(os.PRIO_PROCESS, 0)
    to = may_raise_to(base)
    if to is None:
        pytest.skip("this process may not raise a thread (the server test above covers it)")
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)  # the engine's other stepping thread
    companion = threading.Thread(target=stop.wait)  # as the UR ports' thread
    other.start()
    companion.start()
    seen: list[tuple[int, int, int]] = []

    def sim_thread() -> None:
        me = threading.get_native_id()
        assert other.native_id is not None and companion.native_id is not None
        priority = EnginePriority("auto", lambda: (other.native_id,))
        priority.add_companion(companion.native_id)
        for realtime in (True, False, True):
            priority.follow(realtime)
            priority.follow(realtime)  # no change: nothing to do
            nices = task_nices(os.getpid())
            seen.append((nices[me], nices[other.native_id], nices[companion.native_id]))

    t = threading.Thread(target=sim_thread)
    t.start()
    t.join()
    stop.set()
    other.join()
    companion.join()
    half = max(to, base - COMPANION_STEPS)
    assert seen == [(to, to, half), (base, base, base), (to, to, half)]
