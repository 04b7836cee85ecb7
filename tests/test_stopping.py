"""Stopping saves whatever signals arrive (issue 19): SIGINT or SIGTERM sent to the whole process
group, as a terminal's Ctrl-C or a supervisor does, on every engine configuration.

Each server runs in a process group of its own (as a shell's foreground job) and gets the
signal through `os.killpg`, so shard workers and a local Ray instance get it too. After it:
exit status 0, nothing in the log about shards lost or rebuilt, no traceback, snapshot `latest`
holds the commanded target (and a server started with `--restore latest` serves it), and the
recording that was running is complete and replays bit for bit. A second signal quits at once
(status 128 + signal); a `latest` that cannot be saved makes the exit status 1.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import signal
import termios
import time

import httpx
import psutil
import pytest
from conftest import ELBOW, serve, wait_for

from service.persistence.replay import read_recording, replay_recording
from service.persistence.snapshots import decode_state

TARGET = 0.5  # elbow target [rad] commanded before the signal (within the joint's range)
CONFIGS = {
    "warp": ("--engine", "warp", "--worlds", "4"),
    # worlds 32..63 on a worker process
    "shards": ("--engine", "warp", "--worlds", "64", "--shards", "2"),
    "native": ("--engine", "mujoco", "--worlds", "4"),
    "ray": ("--engine", "warp", "--worlds", "8", "--ray", "local", "--shards", "2"),
}
# Both signals, each configuration once (the signal to the parent alone: test_snapshots,
# test_reliability). Shard workers and Ray's processes are what a group signal adds.
CASES = [
    ("warp", signal.SIGINT),
    ("shards", signal.SIGINT),  # the report: a terminal's Ctrl-C on 64 CPU worlds
    ("native", signal.SIGTERM),
    ("ray", signal.SIGTERM),  # reached Ray's raylet, which stops on SIGTERM even if blocked
]


def _sessions(pid: int) -> set[int]:
    """The sessions of a process and all its descendants (Ray puts its own in new ones)."""
    procs = [psutil.Process(pid), *psutil.Process(pid).children(recursive=True)]
    return {os.getsid(p.pid) for p in procs} - {os.getsid(0)}


def _left_in(sessions: set[int]) -> list[str]:
    """Live processes still in those sessions (zombies are dead, waiting to be reaped)."""
    left = []
    for proc in psutil.process_iter(["name", "status"]):
        with contextlib.suppress(OSError, psutil.Error):
            if os.getsid(proc.pid) in sessions and proc.info["status"] != psutil.STATUS_ZOMBIE:
                left.append(f"{proc.pid} {proc.info['name']}")
    return left


def _clean_exit(srv, sig: int, timeout: float = 120) -> str:
    """Signal the server's whole group; its log once it exited 0 with nothing lost said and
    none of its processes (shard workers, Ray's) left behind."""
    sessions = _sessions(srv.process.pid)
    os.killpg(srv.process.pid, sig)
    code = srv.process.wait(timeout=timeout)
    log = srv.log()
    assert code == 0, log[-3000:]
    for word in ("lost", "rebuil", "Traceback", "SIGTERM received"):
        assert word not in log, log[-3000:]
    wait_for(lambda: not _left_in(sessions), "the service's processes to be gone", timeout=30)
    return log


@pytest.mark.parametrize(
    ("config", "sig"), CASES, ids=[f"{c}-{signal.Signals(s).name}" for c, s in CASES]
)
def test_a_signal_to_the_process_group_saves_latest_and_finishes_the_recording(
    config, sig, tmp_path
):
    if config == "ray":
        pytest.importorskip("ray")
    worlds = int(CONFIGS[config][CONFIGS[config].index("--worlds") + 1])
    world = worlds - 1  # on the last shard: a worker process or actor where there are any
    data = tmp_path / "data"
    args = (*CONFIGS[config], "--data-dir", str(data))
    with serve(worlds=worlds, extra_args=args, log_dir=tmp_path, own_group=True) as srv:
        http = httpx.Client(base_url=srv.url, timeout=60)
        rec = {"name": "run", "worlds": f"0,{world}", "rate": 60}
        assert http.post("/v1/recordings", json=rec).status_code == 201
        with srv.client() as arm:
            ack = arm.set_targets(world, {"elbow_joint": TARGET})
            wait_for(lambda: arm.state(world).tick > ack.tick + 5, "ticks after the command")
        _clean_exit(srv, sig)
    state = decode_state((data / "snapshots" / "latest.npz").read_bytes())  # checks it whole
    assert state.targets[world][ELBOW] == TARGET
    recording = read_recording(data / "recordings" / "run.mcap")
    assert recording.truncated is None  # finished: summary and footer written
    if config in ("shards", "ray"):  # one batch replays what the shards recorded, bit for bit
        assert replay_recording(recording).divergence is None
    if config == "native":  # quick to start: the saved `latest` is served again
        again = (*args, "--restore", "latest", "--mode", "paused")
        with serve(worlds=worlds, extra_args=again, log_dir=tmp_path) as srv:
            served = httpx.get(f"{srv.url}/v1/worlds/{world}/state").json()
        assert served["tick"] == state.tick and served["target"][ELBOW] == TARGET


def test_a_stuck_fifo_fails_the_recording_not_the_loop_and_a_second_signal_quits_at_once(
    tmp_path,
):
    """A recording to a FIFO whose reader stopped reading: the write that finds no room fails
    it within 5 s, with the reason, while the loop goes on; stopping then waits for the writer
    to give up on its last writes, and the second Ctrl-C does not wait."""
    data = tmp_path / "data"
    fifo = data / "recordings" / "stuck.mcap"
    fifo.parent.mkdir(parents=True)
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # open, never read
    try:
        args = (*CONFIGS["native"], "--data-dir", str(data))
        with serve(worlds=4, extra_args=args, log_dir=tmp_path, own_group=True) as srv:
            http = httpx.Client(base_url=srv.url, timeout=30)
            assert (
                http.post("/v1/recordings", json={"name": "stuck", "rate": 60}).status_code == 201
            )

            def queued() -> int:
                buf = bytearray(4)
                fcntl.ioctl(reader, termios.FIONREAD, buf)
                return int.from_bytes(buf, "little")

            # The first chunk (256 KB) fills the pipe (64 KB) and the writer waits for room.
            wait_for(lambda: queued() >= 60000, "the FIFO to fill up", timeout=60)

            def failed() -> dict | None:
                status = http.get("/v1/recordings/current").json()
                return status if status["error"] else None

            status = wait_for(failed, "the recording to give up", timeout=60)
            assert not status["active"] and "no data could be written for 5 s" in status["error"]
            tick = http.get("/v1/worlds/0/state").json()["tick"]
            wait_for(lambda: http.get("/v1/worlds/0/state").json()["tick"] > tick + 30, "ticks")
            os.killpg(srv.process.pid, signal.SIGINT)
            wait_for(lambda: "SIGINT: stopping" in srv.log(), "the first SIGINT to be taken")
            time.sleep(0.2)  # it is now waiting for the stuck writer (up to 5 s per write)
            os.killpg(srv.process.pid, signal.SIGINT)
            code = srv.process.wait(timeout=30)
        log = srv.log()
        assert code == 128 + signal.SIGINT, log[-3000:]
        assert "second SIGINT: quitting at once" in log
        assert "saved snapshot 'latest'" not in log and "Traceback" not in log
    finally:
        os.close(reader)


def test_a_latest_that_cannot_be_saved_makes_the_exit_status_1(tmp_path):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the data folder should be")
    data = blocker / "data"  # mkdir fails (ENOTDIR) whoever runs it, root included
    args = (*CONFIGS["native"], "--data-dir", str(data))
    with serve(worlds=4, extra_args=args, log_dir=tmp_path, own_group=True) as srv:
        os.killpg(srv.process.pid, signal.SIGTERM)
        code = srv.process.wait(timeout=60)
    log = srv.log()
    assert code == 1, log[-3000:]
    assert "stopped, but snapshot 'latest' not saved" in log and "Not a directory" in log, log
    assert "Traceback" not in log
