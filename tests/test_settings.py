"""Settings precedence: a typed `armfleet serve` option > ARMFLEET_* variable > default."""

from __future__ import annotations

import httpx
import pytest
from conftest import running_server


def test_environment_applies_and_a_typed_option_overrides_it(tmp_path, monkeypatch):
    monkeypatch.setenv("ARMFLEET_WORLDS", "3")  # the harness passes --worlds: it must win
    monkeypatch.setenv("ARMFLEET_CONTROL_HZ", "50")  # nobody passes this: the variable applies
    monkeypatch.setenv("ARMFLEET_PHYSICS_DT", "0.004")
    with running_server(tmp_path, worlds=2) as srv:
        info = httpx.get(f"{srv.url}/v1/info").json()
    assert info["nworld"] == 2
    assert info["control_hz"] == 50
    assert info["substeps"] == 5 and info["physics_dt"] == pytest.approx(0.004)


def test_a_bad_environment_value_stops_start_up_naming_the_variable(tmp_path, monkeypatch):
    monkeypatch.setenv("ARMFLEET_CONTROL_HZ", "fast")
    with pytest.raises(RuntimeError, match="control_hz"), running_server(tmp_path):
        pass
