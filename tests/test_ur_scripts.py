"""Which ur_rtde releases' control scripts armfleet recognises, judged by each release's own
code: its `script_client.ScriptClient.sendScript()` (the program `RTDEControlInterface`
uploads, before the register offset is filled in) sends to a socket of the test's, and the
recogniser must take it and name that release. No script text is kept here: each is read from
the wheel at test time.

The installed ur-rtde (the `test` extra: 1.6.5) is always checked. Other releases are checked
when ARMFLEET_UR_RTDE_WHEELS names a folder of their wheels, e.g.
`for v in 0 1 2 3 4; do pip download "ur-rtde==1.6.$v" --no-deps -d /tmp/ur-wheels; done`.
"""

from __future__ import annotations

import importlib.metadata
import os
import socket
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any

import pytest

from service.surfaces.ur import control_script

WHEELS_ENV = "ARMFLEET_UR_RTDE_WHEELS"
SEND = (
    "import script_client, sys; c = script_client.ScriptClient('127.0.0.1', 5, 21, "
    "int(sys.argv[1])); c.connect(); assert c.sendScript(); c.disconnect()"
)


def wheels() -> list[Path]:
    folder = os.environ.get(WHEELS_ENV)
    return sorted(Path(folder).glob("ur_rtde-1.6.*-cp311-*.whl")) if folder else []


def wheel_params() -> list[Any]:
    """One parameter per wheel found, or one skipped parameter saying how to give them."""
    why = f"{WHEELS_ENV} names no folder of ur-rtde 1.6.x wheels (see tests/test_ur_scripts.py)"
    found = [pytest.param(w, id=w.name.split("-")[1]) for w in wheels()]
    return found or [pytest.param(None, id="none", marks=pytest.mark.skip(reason=why))]


def _sent(port_owner: socket.socket, env: dict[str, str]) -> str:
    """What the release's ScriptClient sends to `port_owner` (a listening socket)."""
    port = port_owner.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-c", SEND, str(port)], env=env)
    try:
        port_owner.settimeout(60)
        conn, _ = port_owner.accept()
        with conn:
            conn.settimeout(30)
            data = b""
            while chunk := conn.recv(65536):
                data += chunk
        assert proc.wait(timeout=60) == 0
    finally:
        proc.kill()
    return data.decode()


def _check(release: str, env: dict[str, str]) -> None:
    with socket.create_server(("127.0.0.1", 0)) as server:
        program = _sent(server, env)
    assert program.startswith(control_script.HEADER)
    script = control_script.recognise(program)
    assert script.banner in control_script.KNOWN_BANNERS
    assert release in script.releases, (release, script.versions)


def test_the_installed_ur_rtde_script_is_recognised() -> None:
    pytest.importorskip("script_client")  # the `test` extra: ur-rtde==1.6.5
    _check(importlib.metadata.version("ur_rtde"), dict(os.environ))


@pytest.mark.parametrize("wheel", wheel_params())
def test_each_ur_rtde_1_6_release_script_is_recognised(wheel: Path, tmp_path) -> None:
    release = wheel.name.split("-")[1]
    with zipfile.ZipFile(wheel) as z:
        z.extractall(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}  # the wheel's modules before the venv's
    _check(release, env)
