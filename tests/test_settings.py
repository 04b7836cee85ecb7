"""Settings precedence: a typed `armfleet serve` option > ARMFLEET_* variable > default."""

from __future__ import annotations

import httpx
import pytest
from pydantic import ValidationError

from clients.testing import ServerFailed, serve
from service.settings import Settings


def test_environment_applies_and_a_typed_option_overrides_it(tmp_path, monkeypatch):
    monkeypatch.setenv("ARMFLEET_WORLDS", "3")  # the harness passes --worlds: it must win
    monkeypatch.setenv("ARMFLEET_CONTROL_HZ", "50")  # nobody passes this: the variable applies
    monkeypatch.setenv("ARMFLEET_PHYSICS_DT", "0.004")
    with serve(worlds=2, log_dir=tmp_path) as srv:
        info = httpx.get(f"{srv.url}/v1/info").json()
    assert info["nworld"] == 2
    assert info["control_hz"] == 50
    assert info["substeps"] == 5 and info["physics_dt"] == pytest.approx(0.004)


def test_a_bad_environment_value_stops_start_up_naming_the_variable(tmp_path, monkeypatch):
    monkeypatch.setenv("ARMFLEET_CONTROL_HZ", "fast")
    with pytest.raises(ServerFailed, match="control_hz"), serve(log_dir=tmp_path):
        pass


def test_ray_with_the_native_engine_is_refused_naming_the_field():
    with pytest.raises(ValidationError, match="ray: Ray actors run the warp engine only"):
        Settings(ray="local", engine="mujoco")
    assert Settings(ray="local").engine.ray == "local"
