"""The client library installed on its own (packaging/armfleet-client), as a ROS 2 Humble node,
a notebook or a CI runner would: a wheel built from this checkout, pip-installed with its
dependencies into a fresh venv that has none of the service's packages, then driving a real
`armfleet serve` from a subprocess of that venv's Python. Once with the Python running the tests
and once with Python 3.10 (Humble's) where this machine has one, with Ubuntu 22.04's numpy.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from conftest import ELBOW, HOME, JOINTS, Server
from pythons import ROOT, interpreter

PROJECT = ROOT / "packaging" / "armfleet-client"
ABSENT = (
    "mujoco",
    "mujoco_warp",
    "warp",
    "service",
    "fastapi",
    "cyclonedds",
    "clients.testing",
    "clients.apps",
)
# Ubuntu 22.04's python3-numpy, which rclpy's messages use: the client must work beside it.
HUMBLE_NUMPY = "numpy==1.21.5"
PIP = [sys.executable, "-m", "pip", "--disable-pip-version-check"]

DRIVE = """
import asyncio, json, sys
import clients
import clients.calls, clients.ros_rules, clients.stream, clients.wire  # the public modules
from clients import ArmfleetClient, AsyncArmfleetClient

url, world = sys.argv[1], int(sys.argv[2])
out = {"file": clients.__file__, "python": list(sys.version_info[:2])}
with ArmfleetClient(url, timeout=10) as arm:
    out["joints"] = arm.info().names
    ack = arm.increment(world, "elbow_joint", 0.1)
    out["ack"] = {"target": ack.target.tolist(), "tick": ack.tick}
    state = arm.state(world)
    out["state"] = {"target": state.target.tolist(), "tick": state.tick}
    with arm.connect(world) as session:
        frame = session.recv_state(timeout=10)
        out["frame"] = {"world": frame.world, "tick": frame.tick, "target": frame.target.tolist()}
        out["ws_ack"] = session.increment("elbow_joint", -0.1).target.tolist()

async def nworld():
    async with AsyncArmfleetClient(url, timeout=10) as arm:
        return (await arm.info()).nworld

out["async_nworld"] = asyncio.run(nworld())
print(json.dumps(out))
"""


def outside_env() -> dict[str, str]:
    """This environment without what points Python at the checkout or at armfleet's venv."""
    drop = ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")
    return {k: v for k, v in os.environ.items() if k not in drop}


def check(cmd: list[str | Path], **kw: object) -> str:
    run = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    assert run.returncode == 0, f"{cmd}\n{run.stdout}\n{run.stderr}"
    return run.stdout


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The distribution's wheel, built from a copy of the sources (a build writes into them)."""
    src = tmp_path_factory.mktemp("src")
    shutil.copytree(PROJECT, src / "packaging" / "armfleet-client")
    shutil.copytree(ROOT / "clients", src / "clients", ignore=shutil.ignore_patterns("__pycache__"))
    out = tmp_path_factory.mktemp("wheel")
    check([*PIP, "wheel", "-q", "--no-deps", "-w", out, src / "packaging" / "armfleet-client"])
    (built,) = out.glob("armfleet_client-*.whl")
    return built


def test_the_distribution_is_armfleets_version_and_python_310() -> None:
    ours = tomllib.loads((PROJECT / "pyproject.toml").read_text())["project"]
    theirs = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert ours["version"] == theirs["version"]
    assert ours["requires-python"] == ">=3.10"


@pytest.mark.parametrize("version", ["running", "3.10"])
def test_the_client_alone_drives_a_real_server(
    version: str, wheel: Path, server: Server, tmp_path: Path
) -> None:
    if version == "running":
        python, constraints, world = sys.executable, [], 1
    else:
        python, constraints, world = interpreter((3, 10)), [HUMBLE_NUMPY], 2
        if python is None:
            pytest.skip("no Python 3.10 on this machine (`pyenv install 3.10` gives one)")
    venv = tmp_path / "venv"
    check([python, "-m", "venv", "--without-pip", venv], env=outside_env())
    python_arg = ["--python", venv / "bin" / "python"]
    # --no-compile: pip byte-compiles every installed module (numpy's ~3 CPU-s); the script
    # below imports the client's public modules, which compiles those on this Python anyway.
    install = [*PIP, *python_arg, "install", "-q", "--no-compile", wheel, *constraints]
    check(install, env=outside_env())

    probe = "import importlib.util as u, sys; print([m for m in sys.argv[1:] if u.find_spec(m)])"
    env = outside_env()
    assert check([venv / "bin" / "python", "-c", probe, *ABSENT], env=env, cwd=tmp_path) == "[]\n"

    with server.client() as arm:
        arm.reset(world)
    script = tmp_path / "drive.py"
    script.write_text(DRIVE)
    got = json.loads(check([venv / "bin" / "python", script, server.url, world], env=env))

    assert got["file"].startswith(str(venv)), got["file"]  # the installed copy, not the checkout
    if version == "3.10":
        assert got["python"] == [3, 10]
    assert got["joints"] == JOINTS
    moved = [*HOME[:ELBOW], HOME[ELBOW] + 0.1, *HOME[ELBOW + 1 :]]
    assert got["ack"]["target"] == pytest.approx(moved)
    assert got["state"]["target"] == pytest.approx(moved)  # read-your-writes
    assert got["state"]["tick"] >= got["ack"]["tick"]
    assert got["frame"]["world"] == world and got["frame"]["target"] == pytest.approx(moved)
    assert got["ws_ack"] == pytest.approx(HOME)
    assert got["async_nworld"] == 4
    with server.client() as arm:  # the server really holds what the outside client sent
        assert arm.state(world).target == pytest.approx(HOME)
