"""A real armfleet server for tests: `serve()` starts one, waits until it is ready, stops it.

    from clients.testing import serve

    with serve(worlds=4) as server:
        with server.client() as arm:
            arm.increment(0, "elbow_joint", 0.1)

The server is `python -m service.cli serve` run by this same interpreter, so it is the armfleet
this Python imports (an installed wheel, or a source checkout), on a free 127.0.0.1 port. It is
a separate process with its own simulation loop, exactly as users run it: tests through it
talk over real sockets. With pytest, the `armfleet_server` fixture
(clients/testing/pytest_plugin.py) wraps it. `headless` launches the Chromium that the page's
tests and the bench drive.

A sub-package, not part of the client-only distribution: it starts the service, so it needs the
whole `armfleet`. May import: the client library's public modules (the service only as a child
process, never as an import).
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import httpx

from clients.calls import tls_context
from clients.client import ArmfleetClient
from clients.models import Lease

READY_TIMEOUT = 300.0  # [s] a cold kernel cache compiles for minutes on a small CPU
STOP_TIMEOUT = 15.0  # [s] after SIGINT, before the process is killed
PORT_ATTEMPTS = 3  # free ports tried when the one picked was taken before the server bound it
_PACKAGE_ROOT = Path(__file__).resolve().parents[2]  # holds clients/ and service/


class ServerFailed(RuntimeError):
    """The server exited or did not become ready; the message ends with its log."""


@dataclass
class Server:
    """A running server: where to reach it, its process and its log."""

    url: str  # http://127.0.0.1:PORT
    ws_url: str  # ws://127.0.0.1:PORT
    process: subprocess.Popen[bytes]
    log_path: Path  # stdout and stderr of the server

    @property
    def port(self) -> int:
        return int(self.url.rsplit(":", 1)[1])

    def log(self) -> str:
        """Everything the server printed so far."""
        return self.log_path.read_text(errors="replace")

    def client(self, timeout: float = 10.0) -> ArmfleetClient:
        """A blocking client for this server (close it, or use it in `with`)."""
        return ArmfleetClient(self.url, timeout=timeout)


def free_port() -> int:
    """A TCP port that nothing listens on at 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _child_env(env: Mapping[str, str] | None, data_dir: Path) -> dict[str, str]:
    """os.environ plus `env`; what the server saves (snapshots, recordings) goes to `data_dir`
    unless ARMFLEET_DATA_DIR is set, so a test never writes into the user's own data; a source
    checkout's root goes first on PYTHONPATH so the child imports the same armfleet as this
    process even when started from another directory."""
    out = {"ARMFLEET_DATA_DIR": str(data_dir), **os.environ, **(env or {})}
    if _PACKAGE_ROOT.name not in ("site-packages", "dist-packages"):
        out["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(_PACKAGE_ROOT), out.get("PYTHONPATH")) if p
        )
    return out


def _wait_ready(server: Server, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    with httpx.Client(timeout=1.0, verify=tls_context()) as http:  # (a TLS context: ~45 ms)
        while True:
            if server.process.poll() is not None:
                raise ServerFailed(
                    f"server exited with {server.process.returncode}:\n{server.log()}"
                )
            with contextlib.suppress(httpx.HTTPError):
                if http.get(f"{server.url}/readyz").status_code == 200:
                    return
            if time.monotonic() > deadline:
                raise ServerFailed(f"server not ready after {timeout} s:\n{server.log()}")
            time.sleep(0.2)


def stop(process: subprocess.Popen[bytes], timeout: float = STOP_TIMEOUT) -> int:
    """SIGINT (as Ctrl-C: the server shuts down cleanly), then SIGKILL after `timeout` s.
    Returns the exit status."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


@contextlib.contextmanager
def serve(
    worlds: int = 4,
    mode: str = "realtime",
    port: int | None = None,
    extra_args: Sequence[str] = (),
    env: Mapping[str, str] | None = None,
    log_dir: str | os.PathLike[str] | None = None,
    ready_timeout: float = READY_TIMEOUT,
    stop_timeout: float = STOP_TIMEOUT,
    own_group: bool = False,
    cwd: str | os.PathLike[str] | None = None,
) -> Iterator[Server]:
    """Start `armfleet serve` on 127.0.0.1, yield it once /readyz answers 200, stop it after.

    worlds, mode: as `armfleet serve --worlds --mode`
    port: a fixed port (to restart a server where clients expect it); None picks a free one
        (another, up to PORT_ATTEMPTS times, when something else took it before the server
        could bind it: tests in parallel processes each pick ports)
    extra_args: more `armfleet serve` options, e.g. ("--control-hz", "120")
    env: variables added to this process's environment for the server (ARMFLEET_* settings)
    log_dir: where `server-PORT.log` goes (appended to), and `data-PORT/` (the server's
        ARMFLEET_DATA_DIR unless set); None: a temporary folder, removed when it stops
    own_group: start it in a process group of its own (setsid), as a shell starts a
        foreground job: `os.killpg(server.process.pid, signal.SIGINT)` is then what a
        terminal's Ctrl-C does (every process of the service gets it, workers included)
    cwd: the folder the server starts in; a source checkout's root runs that checkout's
        armfleet (`python -m` puts it first on the path), e.g. to compare two revisions

    Raises ServerFailed (with the log) when the server exits or is not ready in time.
    """
    with contextlib.ExitStack() as stack:
        if log_dir is None:
            log_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="armfleet-"))
        for attempt in range(1, PORT_ATTEMPTS + 1):
            chosen = port or free_port()
            log_path = Path(log_dir) / f"server-{chosen}.log"
            data_dir = Path(log_dir) / f"data-{chosen}"
            cmd = [sys.executable, "-m", "service.cli", "serve", "--worlds", str(worlds)]
            cmd += ["--host", "127.0.0.1", "--port", str(chosen), "--mode", str(mode)]
            with open(log_path, "ab") as log:
                process = subprocess.Popen(
                    [*cmd, *extra_args],
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    env=_child_env(env, data_dir),
                    start_new_session=own_group,
                    cwd=cwd,
                )
            stack.callback(stop, process, stop_timeout)
            url = f"http://127.0.0.1:{chosen}"
            server = Server(url, f"ws://127.0.0.1:{chosen}", process, log_path)
            try:
                _wait_ready(server, ready_timeout)
                break
            except ServerFailed:
                taken = "address already in use" in server.log().lower()
                if (
                    port is not None
                    or attempt == PORT_ATTEMPTS
                    or process.poll() is None
                    or not taken
                ):
                    raise
        yield server


LEASE_WAIT_S = 60.0  # a test waits this long for a free world of a busy shared server
LEASE_TTL_S = 900.0  # a test's lease ends by itself after this, should its process die


@dataclass
class LeasedWorld:
    """One world lent to one test: `client` holds the lease's token, `world` is its id."""

    url: str
    world: int
    lease: Lease
    client: ArmfleetClient


@contextlib.contextmanager
def lease_world(
    url: str, token: str | None = None, label: str = "test", timeout: float = 10.0
) -> Iterator[LeasedWorld]:
    """Borrow one free world of the server at `url` (reset to home) for the block."""
    with (
        ArmfleetClient(url, timeout=timeout, token=token) as lender,
        lender.lease(1, ttl_s=LEASE_TTL_S, label=label, wait_s=LEASE_WAIT_S) as mine,
    ):
        assert mine.leased is not None
        yield LeasedWorld(url, mine.leased.world, mine.leased, mine)
