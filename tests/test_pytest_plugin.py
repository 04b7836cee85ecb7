"""The harness we offer users (`clients.testing`, the `armfleet` pytest plugin), used as a
user would. The first test is the example of docs/guides/testing.md, word for word (tests/
test_docs.py checks that the two are in step)."""

from __future__ import annotations

import importlib
import os
import signal
import tomllib
from pathlib import Path

import httpx
import pytest
from conftest import ROOT

from clients.testing import ServerFailed, pytest_plugin, serve, stop


# -- docs/guides/testing.md: "Testing your controller with pytest" ----------------------------
def test_elbow_settles_on_an_incremented_target(armfleet_server):
    with armfleet_server.client() as arm:
        info = arm.info()  # joint names, limits and home come from the served model
        elbow = info.names.index("elbow_joint")
        arm.reset(1)
        ack = arm.increment(1, "elbow_joint", 0.2)  # takes effect from tick ack.tick on
        assert ack.target[elbow] == pytest.approx(info.home[elbow] + 0.2)

        settled = ack.tick + int(1.5 * info.control_hz)  # 1.5 simulated seconds later
        with arm.connect(1) as world:  # world 1's states over a WebSocket
            state = next(s for s in world if s.tick >= settled)
        assert state.target[elbow] == pytest.approx(ack.target[elbow])
        assert state.position[elbow] == pytest.approx(ack.target[elbow], abs=0.01)


# -- end of the example ------------------------------------------------------------------------


def test_the_module_server_is_four_realtime_worlds_on_loopback(armfleet_server):
    # the testing guide: "a real 4-world server on a free 127.0.0.1 port", ready when given
    assert armfleet_server.url.startswith("http://127.0.0.1:")
    with armfleet_server.client() as arm:
        info = arm.info()
        assert (info.nworld, info.mode) == (4, "realtime")
    assert httpx.get(f"{armfleet_server.url}/readyz").status_code == 200


def test_factory_serves_a_paused_batch_that_steps_exactly(armfleet_server_factory, tmp_path):
    # the testing guide: `env={"ARMFLEET_...": ...}` sets the server's settings
    env = {"ARMFLEET_CONTROL_HZ": "30"}
    server = armfleet_server_factory(worlds=2, mode="paused", log_dir=tmp_path, env=env)
    with server.client() as arm:
        info = arm.info()
        assert (info.nworld, info.mode, info.control_hz) == (2, "paused", 30)
        ack = arm.increment(0, "finger_joint", 0.5)
        stepped = arm.step(30)
        assert stepped.tick == ack.tick + 29  # the command's tick is the first of the 30
        states = arm.states()
        assert states.tick == stepped.tick
        assert states.target[0] == pytest.approx(ack.target)
        assert states.target[1] == pytest.approx(info.home)  # the other world never noticed
    # what the server saves stays with the test unless the caller chose a place
    environ = (Path("/proc") / str(server.process.pid) / "environ").read_bytes().split(b"\0")
    data_dir = os.environ.get("ARMFLEET_DATA_DIR", str(tmp_path / f"data-{server.port}"))
    assert f"ARMFLEET_DATA_DIR={data_dir}".encode() in environ
    # stopped as Ctrl-C stops it (the fixture would do the same after the test)
    assert stop(server.process) in (0, -signal.SIGINT)
    assert (tmp_path / f"server-{server.port}.log").read_text() == server.log()
    assert "Application startup complete" in server.log()


def test_serve_reports_a_server_that_cannot_start(tmp_path):
    with pytest.raises(ServerFailed, match="worlds"), serve(worlds=0, log_dir=tmp_path):
        pass


def test_the_pytest11_entry_point_names_this_plugin():
    """What `pip install armfleet` registers with pytest is the module with our fixtures."""
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    target = meta["project"]["entry-points"]["pytest11"]["armfleet"]
    plugin = importlib.import_module(target)
    assert plugin is pytest_plugin
    assert {"armfleet_server", "armfleet_server_factory"} <= set(vars(plugin))
