"""Shared test helpers. Servers come from the harness we offer users (`clients.testing`,
fixtures in `clients.testing.pytest_plugin`): a real `armfleet serve` process on a free loopback
port; end-to-end tests talk to it over real sockets and nothing of the engine is mocked.

The joint names and home pose are read from the model (the one source of truth), so a test
that compares what the service publishes with them checks the service, not a copy.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import roslibpy
import server_logs
import suite_times

from clients import ArmfleetClient, WorldState
from clients.calls import tls_context
from clients.testing import Server, free_port, headless, serve
from clients.testing import pytest_plugin as armfleet_plugin
from service.core.sim.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]

# The servers the suite starts step native MuJoCo unless a test names the engine: the HTTP,
# WebSocket, ROS and persistence contracts do not depend on it, and a native server is ready
# after about 1.8 s of CPU where MuJoCo Warp's takes about 6 s (importing it and loading its
# kernels), which is most of what a server start costs the suite. The engines are held to one
# contract in-process (test_batch_contract.py); MuJoCo Warp is served end to end where it is
# the subject (test_engine*.py, test_faults.py, test_shards.py, test_stopping.py, the
# `engine`-parametrized tests, replays, Ray) and as the default (test_default_engine.py).
# `ARMFLEET_ENGINE=warp python3 scripts/dev.py test` runs the whole suite's servers on it.
# Tests that build `Settings` in this process read the environment without this
# (`hermetic_settings`).
os.environ.setdefault("ARMFLEET_ENGINE", "mujoco")

# pytest caches each test module as it rewrote its asserts (tests/__pycache__/*-pytest-*.pyc,
# ignored by git, written atomically so that xdist workers may race) unless Python is told not
# to write bytecode, as PYTHONDONTWRITEBYTECODE does in this project's shared work sessions:
# then every worker rewrote and compiled all ~110 test modules at each run, about 3 s of CPU a
# worker. scripts/dev.py byte-compiles the sources regardless, for the same reason.
sys.dont_write_bytecode = False

SPEC = load_robot().spec
JOINTS: list[str] = list(SPEC.names)
HOME: list[float] = SPEC.home.tolist()
ELBOW, FINGER = SPEC.index("elbow_joint"), SPEC.index("finger_joint")

__all__ = ["ELBOW", "FINGER", "HOME", "JOINTS", "ROOT", "Server", "free_port", "serve"]


def running_server(
    tmp_path: Path,
    worlds: int = 4,
    mode: str = "realtime",
    port: int | None = None,
    extra: tuple[str, ...] = (),
) -> contextlib.AbstractContextManager[Server]:
    """The old name and argument order of `serve`, kept for branches written against it."""
    return serve(worlds=worlds, mode=mode, port=port, extra_args=extra, log_dir=tmp_path)


def pytest_configure(config: pytest.Config) -> None:
    """Our fixtures are the `armfleet` plugin users get through the pytest11 entry point;
    register it here too when that entry point is not installed (a plain checkout), so the
    suite does not depend on how armfleet was installed. (`pytest_plugins = [...]` would
    clash with the entry point: pytest refuses a module registered under two names.)"""
    if not config.pluginmanager.is_registered(armfleet_plugin):
        config.pluginmanager.register(armfleet_plugin, "armfleet")
    suite_times.pytest_configure(config)  # with workers: where the time went, by file
    config.addinivalue_line(
        "markers",
        f"{server_logs.MARKER}(reason): this test makes a server of its own (logging under its "
        "tmp_path) print a traceback on purpose; the end-of-run log check skips those logs",
    )


# -- the servers' logs: no traceback, no logging error (tests/server_logs.py) ------------------

_LOG_PROBLEMS = "armfleet_server_log_problems"  # a worker's findings, for the controller
_FOUND = pytest.StashKey[list[str]]()  # this process's findings (a controller: its workers')


@pytest.fixture(autouse=True)
def _server_traceback_expected(request: pytest.FixtureRequest) -> None:
    """A test marked `server_traceback(reason)`: the logs under its tmp_path are excused."""
    mark = request.node.get_closest_marker(server_logs.MARKER)
    if mark is not None:
        assert mark.args and mark.args[0], f"@pytest.mark.{server_logs.MARKER} needs a reason"
        tmp = request.getfixturevalue("tmp_path")
        server_logs.excused(request.config)[tmp] = str(mark.args[0])


def _is_xdist_controller(config: pytest.Config) -> bool:
    return not hasattr(config, "workerinput") and bool(getattr(config.option, "numprocesses", 0))


@pytest.hookimpl(tryfirst=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Read every server log this process's tests left (a worker: its own) and fail the run
    when one has a traceback or a logging error; a worker hands its findings to the
    controller (pytest_testnodedown), which fails the run and prints them."""
    config = session.config
    found = config.stash.setdefault(_FOUND, [])
    if not _is_xdist_controller(config):
        root = config._tmp_path_factory.getbasetemp()  # type: ignore[attr-defined]
        found += server_logs.problems(root, server_logs.excused(config))
        if hasattr(config, "workeroutput"):
            config.workeroutput[_LOG_PROBLEMS] = found  # type: ignore[attr-defined]
            return
    if found and session.exitstatus == pytest.ExitCode.OK:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


@pytest.hookimpl(optionalhook=True)  # a pytest-xdist hook: unknown where xdist is not loaded
def pytest_testnodedown(node: Any, error: object) -> None:
    """pytest-xdist's controller: a worker's findings (see pytest_sessionfinish)."""
    output = getattr(node, "workeroutput", {})
    node.config.stash.setdefault(_FOUND, []).extend(output.get(_LOG_PROBLEMS, []))


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    found = config.stash.get(_FOUND, [])
    if found:
        terminalreporter.section("tracebacks in the servers' logs", red=True, bold=True)
        for finding in found:
            terminalreporter.write_line(finding)
            terminalreporter.write_line("")


# The test files that take longest, longest first: they run before the others, so that with
# pytest-xdist (`scripts/dev.py test`: --dist loadfile --no-loadscope-reorder hands out files
# in collection order) no long file starts last and keeps one worker busy while others idle.
# The two schemathesis files lead: each alone, nice'd at load 8-10, test_leases took 480 s and
# 153 CPU-s, test_contract 322 s and 117 CPU-s, the next one 198 s (a run's end shows the
# order's effect: tests/suite_times.py).
LONGEST_FIRST = (
    "test_leases.py",
    "test_contract.py",
    "test_batch_contract.py",
    "test_ray_hosts.py",
    "test_ros_node.py",
    "test_ros_node_supervision.py",
    "test_params.py",
    "test_ray_shards.py",
    "test_stopping.py",
    "test_page.py",
    "test_docs.py",
    "test_recording.py",
    "test_ws_bulk.py",
    "test_engine_worker.py",
    "test_randomize.py",
    "test_ur_control.py",
    "test_faults.py",
    "test_engine.py",
    "test_shards.py",
    "test_client_dist.py",
    "test_soak.py",
    "test_capacity_command.py",
    "test_your_cell.py",
    "test_cameras.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: files stay whole


@pytest.fixture
def hermetic_settings(monkeypatch: pytest.MonkeyPatch) -> None:
    """No `ARMFLEET_*` variable of the caller's (or of this suite's engine choice above) reaches
    a `Settings` built in this process: a test of the defaults sees the defaults."""
    for name in list(os.environ):
        if name.startswith("ARMFLEET_"):
            monkeypatch.delenv(name)


def cameras_ready(tmp_path_factory: pytest.TempPathFactory, name: str) -> Iterator[Server]:
    """A 4-world server on the CPU default, handed over once its cameras are ready: the camera
    tests' module fixtures (`yield from`)."""
    with serve(worlds=4, log_dir=tmp_path_factory.mktemp(name)) as s:
        cameras_warmed(s.url)
        yield s


def cameras_warmed(url: str, headers: dict[str, str] | None = None) -> None:
    """Until the server's camera renderer is built and has drawn every camera once (on the CPU
    the first ask starts the build: 15 s for 32 worlds at load 11). A warming server answers
    slowly on a loaded box: 60 s a read, 300 s in all. Asked on one connection four times a
    second: a new connection every 50 ms cost the suite ~2 CPU-s a server (client and server
    side) over a build of 20-40 s on the 2-core box."""
    tls = tls_context()  # (httpx builds one per client otherwise: ~45 ms of CPU)
    with httpx.Client(base_url=url, headers=headers, timeout=60, verify=tls) as http:
        wait_for(lambda: http.get("/v1/cameras").json()["ready"], "cameras", 300, interval=0.25)


def wait_for(
    pred: Callable[[], Any], what: str, timeout: float = 15, interval: float = 0.05
) -> Any:
    """Poll `pred` every `interval` s until it returns something truthy; fail naming `what`
    after `timeout` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = pred()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(interval)


_PRESTART = "RAY_prestart_worker_first_driver"


@contextlib.contextmanager
def local_ray(num_cpus: int = 4) -> Iterator[None]:
    """A private Ray instance on 127.0.0.1 (what `serve --ray local` starts) for one module's
    tests, every process of it killed at the end. Left running, an idle instance cost its xdist
    worker about 1.7 CPU-s a minute (GCS, raylet, monitors, idle workers) until the run ended,
    where starting one costs about 10; an instance already running here is used and left."""
    import ray

    from service.engines import ray_local
    from service.engines.ray_actor import connect

    ours = not ray.is_initialized()
    # No workers started ahead for this driver: the shard actors started workers of their own
    # while those idled (ps), each ~0.65 CPU-s to start and ~0.4 a minute idle. Read by the
    # raylet as it starts, so set for the start only (servers started later keep Ray's default).
    before = os.environ.get(_PRESTART)
    os.environ[_PRESTART] = "0"
    try:
        with ray_local.starting():  # its processes in sessions of their own: all of them stopped
            connect("local", num_cpus=num_cpus)
    finally:
        if before is None:
            del os.environ[_PRESTART]
        else:
            os.environ[_PRESTART] = before
    try:
        yield
    finally:
        if ours:
            ray_local.stop_local_instance()


def metric(http: httpx.Client, name: str) -> float:
    """The value of counter or gauge `name` (with its labels, if any: `x{source="http"}`; a
    bare name takes the first labelled sample) in the server's /metrics."""
    for line in http.get("/metrics").text.splitlines():
        if line.startswith(name + " ") or line.startswith(name + "{"):
            return float(line.rsplit(" ", 1)[1])
    raise AssertionError(f"{name} not in /metrics")


def replies_of(ws: Any, n: int, ops: tuple[str, ...] = ("ack", "error")) -> list[dict[str, Any]]:
    """The next `n` messages of a command socket (websockets' sync client) whose op is in
    `ops`, in order; state frames and other ops in between are passed over."""
    replies: list[dict[str, Any]] = []
    while len(replies) < n:
        msg = json.loads(ws.recv(timeout=5))
        if msg["op"] in ops:
            replies.append(msg)
    return replies


def node_armfleet(seen: dict[str, Any], owned: dict[str, str]) -> dict[str, Any]:
    """Node /armfleet from a peer's `ros_discovery_info` view (`seen`: 'nodes', and the GUIDs
    DDS discovery reported as 'writers'/'readers' by topic), checked to own exactly one
    endpoint on each topic of `owned` (topic -> 'writers' or 'readers'): how `ros2 node list`
    and `ros2 topic info -v` attribute them. Node GIDs are the 16-byte GUID padded to 24."""
    (node,) = [n for n in seen["nodes"] if n["name"] == "armfleet"]
    assert node["namespace"] == "/"
    for topic, kind in owned.items():
        ours = [g for g in seen[kind].get(topic, []) if g + "00" * 8 in node[kind]]
        assert len(ours) == 1, (topic, seen[kind].get(topic), node[kind])
    return node


def target_after(client: ArmfleetClient, world: int, pred: Callable[[WorldState], bool]) -> Any:
    """The world's targets once `pred(state)` holds (commands apply at the next tick)."""

    def check() -> WorldState | None:
        state = client.state(world)
        return state if pred(state) else None

    return wait_for(check, f"world {world}'s target to change").target


@pytest.fixture(scope="module")
def server(armfleet_server: Server) -> Iterator[Server]:
    """The 4-world realtime server shared by the tests of one module (`armfleet_server`)."""
    yield armfleet_server


@pytest.fixture(scope="module")
def paused(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """A paused 4-world server on native MuJoCo (ticks advance only when a test steps them),
    shared by the tests of one module; a module that needs more of it defines its own."""
    log = tmp_path_factory.mktemp("paused")
    with serve(worlds=4, mode="paused", extra_args=("--engine", "mujoco"), log_dir=log) as srv:
        yield srv


@pytest.fixture(scope="module")
def http(server: Server) -> Iterator[httpx.Client]:
    """An HTTP client on the module's server."""
    with httpx.Client(base_url=server.url, timeout=10, verify=tls_context()) as client:
        yield client


@pytest.fixture(scope="module")
def ros(server: Server) -> Iterator[roslibpy.Ros]:
    """roslibpy (a real rosbridge client) connected to the module's server, as rosbridge
    clients dial it (`ws://host:port/`); closed when the module is done."""
    client = roslibpy.Ros("127.0.0.1", server.port)
    client.run(timeout=20)
    try:
        yield client
    finally:
        client.close()


# -- Chromium (Playwright), the judge of the browser page ------------------------------------


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Debian's Chromium through Playwright, one for the module (skipped, saying why, where
    it cannot run)."""
    reason = headless.why_unavailable()
    if reason:
        pytest.skip(reason)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        chromium = headless.launch(p)
        yield chromium
        chromium.close()


@pytest.fixture(scope="module")
def page_context(browser: Any) -> Iterator[Any]:
    """A browser context with a 1000 x 640 viewport that a module's pages share, each test's a
    tab of its own (`page_in`: the page keeps nothing but its sessionStorage, per tab)."""
    context = browser.new_context(viewport={"width": 1000, "height": 640})
    yield context
    context.close()


@contextlib.contextmanager
def page_of(browser: Any, width: int, height: int) -> Iterator[Any]:
    """A page in a fresh context of `browser` with a `width` x `height` viewport; a JavaScript
    error the page threw fails the test once it is done with the page."""
    context = browser.new_context(viewport={"width": width, "height": height})
    try:
        with page_in(context) as page:
            yield page
    finally:
        context.close()


@contextlib.contextmanager
def page_in(context: Any) -> Iterator[Any]:
    """A new page (a tab of its own: its own sessionStorage, sockets and scripts) in a browser
    context that a module's tests share; a JavaScript error the page threw fails the test once
    it is done with the page. A context of its own for each test cost Chromium ~0.3-0.5 s of
    CPU more a page (a context is a new profile: its caches start empty)."""
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    try:
        yield page
    finally:
        page.close()  # its sockets too: a failed test's page does not stream on
    assert not errors, f"JavaScript errors in the page: {errors}"


# -- roslib.js (tests/js: Node scripts that drive the rosbridge endpoint) ---------------------

JS_DIR = Path(__file__).with_name("js")


@pytest.fixture(scope="session")
def roslibjs() -> Callable[..., tuple[dict[str, Any], str]]:
    """Runs a tests/js script with roslib.js installed (else the test is skipped): what it
    printed last, as JSON, and its stderr (for the assertion message)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("node/npm not installed")
    if not (JS_DIR / "node_modules" / "roslib").exists():
        subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=JS_DIR, check=True)

    def run(script: str, *args: str) -> tuple[dict[str, Any], str]:
        out = subprocess.run(
            [node, script, *args], cwd=JS_DIR, capture_output=True, text=True, timeout=60
        )
        return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr

    return run
