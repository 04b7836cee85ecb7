"""The README's five-minute tour, run as written against a real server: its `curl` block, its
Python block and its pytest example (blocks marked `<!-- tour:NAME -->` in README.md). Only the
address changes: the server listens on a free port instead of 8000. Each step must move an arm.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from clients.testing import Server, serve

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MOVED = 0.05  # [rad] of the 0.5 rad commanded


def tour_block(name: str) -> str:
    """The fenced block right after `<!-- tour:NAME -->` in the README."""
    found = re.search(rf"<!-- tour:{name} -->\n```\w*\n(.*?)```", README.read_text(), re.S)
    assert found, f"README has no tour block {name!r}"
    return found.group(1)


def at(port: int, text: str) -> str:
    """The block pointed at the test's server instead of port 8000."""
    return re.sub(r"(localhost|127\.0\.0\.1):8000", f"127.0.0.1:{port}", text)


def documents(text: str) -> list[dict]:
    """The JSON documents curl printed one after the other (curl adds no newline)."""
    decoder, found, at_ = json.JSONDecoder(), [], 0
    while text[at_:].strip():
        doc, end = decoder.raw_decode(text, at_ + len(text[at_:]) - len(text[at_:].lstrip()))
        found.append(doc)
        at_ = end
    return found


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    with serve(worlds=4, log_dir=tmp_path_factory.mktemp("tour")) as running:
        yield running


def elbow(server: Server, world: int) -> tuple[float, float, float]:
    """(home, target, position) of the world's elbow, read over HTTP."""
    with server.client() as arm:
        info, state = arm.info(), arm.state(world)
        i = info.names.index("elbow_joint")
        return info.home[i], state.target[i], state.position[i]


@pytest.mark.skipif(shutil.which("curl") is None, reason="curl is not installed")
def test_the_curl_step_moves_world_0(server: Server) -> None:
    block = tour_block("curl")
    assert "curl" in block and "/increments" in block
    done = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", at(server.port, block)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    reply, state = documents(done.stdout)
    home, target, position = elbow(server, 0)
    i = state["name"].index("elbow_joint")
    # up, away from the table: +0.5 folds the gripper 4 cm into it, a protective stop
    assert reply["target"][i] == pytest.approx(home - 0.5) == target
    # what the user reads: a second later the elbow is on its way (how far depends on the
    # machine's speed in real time; a tenth of the way is far beyond any noise)
    assert home - state["position"][i] > MOVED
    assert home - position > MOVED


def test_the_python_step_moves_world_1(server: Server) -> None:
    block = tour_block("python")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", at(server.port, block)],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr
    assert "target from tick" in done.stdout and "elbow at" in done.stdout
    home, target, position = elbow(server, 1)
    assert target == pytest.approx(home - 0.5)
    printed = float(re.search(r"elbow at (\S+)", done.stdout).group(1))  # type: ignore[union-attr]
    assert home - printed > MOVED and home - position > MOVED


def test_the_pytest_step_passes_as_a_users_test_file(tmp_path: Path) -> None:
    """The fixture example, saved as the README says and run by pytest in a fresh directory
    (the `armfleet` plugin starts its own server)."""
    (tmp_path / "test_arm.py").write_text(tour_block("pytest"))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # (without this venv's plugins that the file does not use: a third of the start's CPU)
    unused = ["-p", "no:schemathesis", "-p", "no:hypothesispytest", "-p", "no:anyio"]
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *unused]
    command += ["test_arm.py"]
    done = subprocess.run(
        command, capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path
    )
    if "fixture 'armfleet_server' not found" in done.stdout:
        # a plain checkout, armfleet not installed: name the plugin its entry point would load
        command[4:4] = ["-p", "clients.testing.pytest_plugin"]
        done = subprocess.run(
            command, capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path
        )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1 passed" in done.stdout
