"""Settings precedence: a typed `armfleet serve` option > ARMFLEET_* variable > default."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import httpx
import pytest
from pydantic import ValidationError

from clients.testing import ServerFailed, serve
from service.settings import Settings

pytestmark = pytest.mark.usefixtures("hermetic_settings")  # Settings built here read no env

ROOT = Path(__file__).resolve().parents[1]


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


def test_the_settings_import_no_engine():
    """Reading the settings starts no Warp (a CUDA device is checked where the engine starts)."""
    code = (
        "import sys; from service.settings import Settings; Settings(camera_device='cuda:7'); "
        "print(sorted(m for m in ('warp', 'mujoco_warp', 'ray') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


def test_a_section_given_whole_and_a_flat_name_beside_it():
    from service.core.sim.settings import SimSettings

    settings = Settings(sim=SimSettings(worlds=3, control_hz=30), worlds=5)
    assert (settings.sim.worlds, settings.sim.control_hz) == (5, 30)  # the flat name wins
    assert Settings(foxglove={"port": 9000}).foxglove.port == 9000  # a mapping is the section
    assert Settings(foxglove=True).foxglove.enabled  # a flat value is the flat setting
    with pytest.raises(ValidationError, match="nonsense"):
        Settings(nonsense=1)


def test_a_bad_value_is_named_by_its_flat_name(monkeypatch):
    """What serve prints: the name the user typed (the option, the variable), not the section."""
    from service.settings import flat_name

    with pytest.raises(ValidationError) as caught:
        Settings(foxglove_port=-1)
    (err,) = caught.value.errors()
    assert flat_name(tuple(err["loc"])) == "foxglove_port"
    with pytest.raises(ValidationError) as caught:
        Settings(leases="required")  # a section's own check: its message names the setting
    (err,) = caught.value.errors()
    assert flat_name(tuple(err["loc"])) == ""
    assert "leases required: give --token" in err["msg"]
