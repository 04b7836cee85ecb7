"""Failures to write reach the caller (issue 19): a recording or snapshot that cannot be written
is a 507 naming the cause, never an "active" recording that is not; `serve --record` to such a
path stops before anything is built; a full disk leaves the previous `latest` intact.

The unwritable and full folders are real file systems: a read-only tmpfs and a small tmpfs that
the test mounts (tests run as root here; where mounting is not allowed they are skipped, saying
so), and a FIFO that nobody opened for reading. Chmod would not do: root writes anyway.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from conftest import ROOT, free_port, serve, wait_for

from service.persistence.snapshots import decode_state

NATIVE = ("--engine", "mujoco")  # starts in a second; how files are written is the same


@contextlib.contextmanager
def tmpfs(target: Path, options: str) -> Iterator[Path]:
    """A tmpfs mounted at `target` for the block (skips the test where mounting is refused)."""
    target.mkdir(parents=True, exist_ok=True)
    cmd = ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(target)]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    except FileNotFoundError:
        pytest.skip("no `mount` command: cannot make a read-only or full file system")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {done.stderr.strip()}")
    try:
        yield target
    finally:
        subprocess.run(["umount", "-l", str(target)], check=False, timeout=30)


def test_a_recording_that_cannot_be_written_is_refused_naming_the_cause(tmp_path):
    data = tmp_path / "data"
    recordings = data / "recordings"
    recordings.mkdir(parents=True)
    os.mkfifo(recordings / "nobody.mcap")
    args = (*NATIVE, "--data-dir", str(data))
    with serve(worlds=2, mode="paused", extra_args=args, log_dir=tmp_path) as srv:
        http = httpx.Client(base_url=srv.url, timeout=30)
        r = http.post("/v1/recordings", json={"name": "nobody"})
        assert r.status_code == 507, r.text
        assert "no process has the FIFO open for reading" in r.json()["detail"]
        assert "nobody.mcap" in r.json()["detail"]
        with tmpfs(recordings, "ro"):
            r = http.post("/v1/recordings", json={"name": "run"})
            assert r.status_code == 507, r.text
            assert "Read-only file system" in r.json()["detail"]
            # Nothing half-started: no recording runs, and one that can be written still starts.
            assert http.get("/v1/recordings/current").status_code == 404
        assert http.post("/v1/recordings", json={"name": "run"}).status_code == 201
        assert http.delete("/v1/recordings/current").status_code == 200
    assert "Traceback" not in srv.log()


def test_serve_record_to_an_unwritable_path_stops_before_starting(tmp_path):
    with tmpfs(tmp_path / "ro", "ro") as folder:
        cmd = [sys.executable, "-m", "service.cli", "serve", *NATIVE, "--worlds", "1"]
        cmd += ["--port", str(free_port()), "--record", str(folder / "run.mcap")]
        env = {**os.environ, "ARMFLEET_DATA_DIR": str(tmp_path / "data")}
        done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert f"cannot write recording {folder / 'run.mcap'}: Read-only file system" in done.stderr
    assert "Traceback" not in done.stderr


def _fill(folder: Path) -> None:
    """Write a file in `folder` until the file system says it is full."""
    with open(folder / "filler", "wb", buffering=0) as f:
        with contextlib.suppress(OSError):
            while True:
                f.write(b"\0" * 65536)
        with contextlib.suppress(OSError):
            while True:
                f.write(b"\0" * 512)


def test_a_full_disk_keeps_the_previous_latest_and_says_so(tmp_path):
    with tmpfs(tmp_path / "data", "size=2m") as data:
        args = (*NATIVE, "--data-dir", str(data))
        with serve(worlds=8, mode="paused", extra_args=args, log_dir=tmp_path) as srv:
            http = httpx.Client(base_url=srv.url, timeout=60)
            assert http.post("/v1/snapshots", json={"name": "latest"}).status_code == 201
            latest = data / "snapshots" / "latest.npz"
            before = latest.read_bytes()
            rec = {"name": "run", "rate": 60}
            assert http.post("/v1/recordings", json=rec).status_code == 201
            _fill(data)
            http.post("/v1/worlds/3/increments", json={"joint": 2, "delta": 0.3})
            r = http.post("/v1/snapshots", json={"name": "latest"})
            assert r.status_code == 507, r.text
            assert "No space left on device" in r.json()["detail"]
            assert "any earlier 'latest' is kept" in r.json()["detail"]
            assert latest.read_bytes() == before
            # The running recording fails as soon as its next block cannot be written...
            http.post("/v1/sim/step", json={"ticks": 1200}).raise_for_status()

            def failed() -> dict | None:
                status = http.get("/v1/recordings/current").json()
                return status if status["error"] else None

            status = wait_for(failed, "the recording to fail")
            assert not status["active"] and "No space left on device" in status["error"]
            # ... a stop asked for afterwards names why there is nothing to stop ...
            r = http.delete("/v1/recordings/current")
            assert r.status_code == 404 and "No space left on device" in r.json()["detail"]
            # ... and a new one is refused at once.
            r = http.post("/v1/recordings", json={"name": "again"})
            assert r.status_code == 507 and "No space left on device" in r.text, r.text
            srv.process.send_signal(signal.SIGINT)
            code = srv.process.wait(timeout=60)
        log = srv.log()
        assert code == 1, log[-3000:]  # `latest` not saved, the recording incomplete
        assert "stopped, but snapshot 'latest' not saved" in log and "Traceback" not in log
        assert latest.read_bytes() == before
        decode_state(before)  # and it is a whole snapshot
