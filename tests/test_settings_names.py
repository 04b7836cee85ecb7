"""Every ARMFLEET_* variable and `armfleet serve` option of today keeps setting what it set.

Why frozen here: the settings were one flat model of 52 fields (issue 37 nests them beside their
owners). The names below, and what a value of each sets, were generated from that flat model
before it changed (each value checked through the variable alone, then through the option with
the variable also set: the option wins), so a rename or a lost mapping fails here by name.
"""

from __future__ import annotations

import enum
from pathlib import Path
from typing import Any

import pytest
from typer.main import get_command
from typer.testing import CliRunner

from mjcf import SCENE_XML
from service.cli import app

pytestmark = pytest.mark.usefixtures("hermetic_settings")  # Settings built here read no env

SERVE_OPTIONS = [
    "--allow-origins",
    "--camera-batch",
    "--camera-device",
    "--camera-outputs",
    "--camera-rate",
    "--camera-record",
    "--camera-record-cameras",
    "--camera-record-worlds",
    "--camera-size",
    "--cameras",
    "--command-burst",
    "--command-rate",
    "--control-hz",
    "--data-dir",
    "--device",
    "--engine",
    "--engine-priority",
    "--engine-worker",
    "--foxglove",
    "--foxglove-cameras",
    "--foxglove-port",
    "--foxglove-rate",
    "--foxglove-worlds",
    "--host",
    "--insecure",
    "--lease-max-ttl-s",
    "--lease-reset",
    "--leases",
    "--log-level",
    "--max-body-bytes",
    "--max-clients",
    "--mode",
    "--no-engine-worker",
    "--no-foxglove",
    "--no-insecure",
    "--no-ros2",
    "--no-save-on-exit",
    "--no-token-reads",
    "--no-ws-compression",
    "--physics-dt",
    "--port",
    "--ray",
    "--ray-checkpoint-s",
    "--record",
    "--record-queue",
    "--record-rate",
    "--record-worlds",
    "--restore",
    "--ros2",
    "--ros2-cameras",
    "--ros2-python",
    "--ros2-rate",
    "--ros2-worlds",
    "--save-on-exit",
    "--scene",
    "--shards",
    "--token",
    "--token-reads",
    "--worlds",
    "--ws-compression",
]

# (field, ARMFLEET_<FIELD> text, what it sets, `--<field>` text, what the option sets), for
# the fields whose value is neither a number, on/off, nor the text itself.
PARSED: list[tuple[str, str, Any, str, Any]] = [
    (
        "allow_origins",
        '["https://a.example"]',
        ["https://a.example"],
        "https://b.example",
        ["https://b.example"],
    ),
]
# (field, ARMFLEET_<FIELD> text, `--<field>` text, the number type both set the field to).
NUMBERS: list[tuple[str, str, str, type]] = [
    ("worlds", "3", "5", int),
    ("port", "9001", "9002", int),
    ("shards", "2", "3", int),
    ("ray_checkpoint_s", "2.5", "4", float),
    ("control_hz", "50", "125.5", float),
    ("physics_dt", "0.004", "0.001", float),
    ("max_body_bytes", "2048", "4096", int),
    ("max_clients", "5", "7", int),
    ("command_rate", "20", "30", float),
    ("command_burst", "4", "6", int),
    ("lease_max_ttl_s", "60", "120", float),
    ("record_rate", "10", "20", float),
    ("record_queue", "64", "128", int),
    ("foxglove_port", "9765", "9766", int),
    ("foxglove_rate", "15", "20", float),
    ("ros2_rate", "30", "40", float),
    ("camera_batch", "4", "8", int),
    ("camera_rate", "5", "2.5", float),
]
# On/off fields: what ARMFLEET_<FIELD> sets ("true" or "false"); the option then sets the other.
FLAGS: dict[str, bool] = {
    "engine_worker": True,
    "ws_compression": True,
    "insecure": True,
    "token_reads": True,
    "save_on_exit": False,
    "foxglove": True,
    "ros2": True,
}
# (field, ARMFLEET_<FIELD> text, `--<field>` text), for the fields that keep the text as written;
# {SCENE}: the default scene's path, {ROOT}: the checkout's.
AS_WRITTEN: list[tuple[str, str, str]] = [
    ("engine", "mujoco", "warp"),
    ("device", "cuda:1", "cuda"),
    ("host", "10.0.0.1", "0.0.0.0"),
    ("ray", "local", "auto"),
    ("scene", "{SCENE}", "{ROOT}/mjcf/../mjcf/scene.xml"),
    ("mode", "fast", "paused"),
    ("engine_priority", "off", "auto"),
    ("log_level", "debug", "error"),
    ("token", "secret-a", "secret-b"),
    ("leases", "optional", "off"),
    ("lease_reset", "start", "end"),
    ("data_dir", "/tmp/af-a", "/tmp/af-b"),
    ("restore", "latest", "snap1"),
    ("record", "/tmp/a.mcap", "/tmp/b.mcap"),
    ("record_worlds", "0-3", "1,2"),
    ("foxglove_worlds", "0-1", "2"),
    ("ros2_worlds", "0-1", "1"),
    ("ros2_python", "/usr/bin/python3", "/opt/py"),
    ("camera_size", "64x48", "32x24"),
    ("camera_outputs", "rgb", "depth,seg"),
    ("cameras", "wrist=off", "overview=32x24:rgb"),
    ("camera_device", "cpu", ""),
    ("foxglove_cameras", "wrist", "overview"),
    ("camera_record", "/tmp/c.mcap", "/tmp/d.mcap"),
    ("ros2_cameras", "wrist", "overview"),
    ("camera_record_cameras", "overview", "wrist,overview"),
    ("camera_record_worlds", "1", "0-1"),
]
VALUES = (
    PARSED
    + [(name, env, kind(env), cli, kind(cli)) for name, env, cli, kind in NUMBERS]
    + [(name, str(on).lower(), on, str(not on).lower(), not on) for name, on in FLAGS.items()]
    + [(name, env, env, cli, cli) for name, env, cli in AS_WRITTEN]
)
DEFAULTS: dict[str, Any] = {
    "worlds": 16,
    "engine": "warp",
    "device": "cpu",
    "host": "127.0.0.1",
    "port": 8000,
    "shards": 0,
    "engine_worker": False,
    "ray": None,
    "ray_checkpoint_s": 10.0,
    "scene": None,
    "mode": "realtime",
    "control_hz": 60.0,
    "physics_dt": 0.008333333333333333,
    "engine_priority": "auto",
    "max_body_bytes": 1048576,
    "ws_compression": False,
    "log_level": "info",
    "token": None,
    "insecure": False,
    "token_reads": False,
    "allow_origins": [],
    "max_clients": 256,
    "command_rate": 200.0,
    "command_burst": None,
    "leases": "off",
    "lease_reset": "both",
    "lease_max_ttl_s": 86400.0,
    "data_dir": "~/.local/share/armfleet",
    "restore": None,
    "save_on_exit": True,
    "record": None,
    "record_worlds": None,
    "record_rate": 30.0,
    "record_queue": 2048,
    "foxglove": False,
    "foxglove_port": 8765,
    "foxglove_worlds": None,
    "foxglove_rate": 30.0,
    "ros2": False,
    "ros2_rate": 60.0,
    "ros2_worlds": "",
    "ros2_python": None,
    "camera_size": "128x96",
    "camera_outputs": "rgb,depth",
    "cameras": "",
    "camera_batch": 16,
    "camera_device": "",
    "camera_rate": 10.0,
    "foxglove_cameras": "",
    "camera_record": None,
    "ros2_cameras": "",
    "camera_record_cameras": "wrist",
    "camera_record_worlds": "0",
}
NEEDS = {"leases": {"token": "t"}, "camera_record_worlds": {"camera_record": "/tmp/c.mcap"}}
BOOLS = set(FLAGS)


def _here(value: Any) -> Any:
    if isinstance(value, str):
        return value.replace("{SCENE}", str(SCENE_XML)).replace(
            "{ROOT}", str(SCENE_XML.parent.parent)
        )
    return value


def _plain(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.value
    return str(value) if isinstance(value, Path) else value


def _read(settings: Any, name: str) -> Any:
    """The value the flat name `name` set: the field of its section (service/settings.py)."""
    from service.settings import flat_fields

    section, field, _ = flat_fields()[name]
    return _plain(getattr(getattr(settings, section), field))


def _flag(name: str, text: str) -> list[str]:
    option = "--" + name.replace("_", "-")
    if name in BOOLS:
        return [option if text == "true" else "--no-" + name.replace("_", "-")]
    return [option, _here(text)]


@pytest.fixture(autouse=True)
def _no_armfleet_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    for key in list(os.environ):
        if key.startswith("ARMFLEET_"):
            monkeypatch.delenv(key)


def test_every_serve_option_of_today_is_still_there() -> None:
    serve = get_command(app).commands["serve"]  # type: ignore[attr-defined]
    now = {o for p in serve.params for o in (*p.opts, *p.secondary_opts)}
    assert set(SERVE_OPTIONS) <= now, sorted(set(SERVE_OPTIONS) - now)


@pytest.mark.parametrize(("name", "env_text", "env_value"), [r[:3] for r in VALUES])
def test_each_variable_sets_what_it_set(monkeypatch, name: str, env_text: str, env_value) -> None:
    from service.settings import Settings

    monkeypatch.setenv(f"ARMFLEET_{name.upper()}", _here(env_text))
    settings = Settings(**NEEDS.get(name, {}))
    assert _read(settings, name) == _here(env_value)


@pytest.mark.parametrize(
    ("name", "env_text", "cli_text", "cli_value"), [r[:2] + r[3:] for r in VALUES]
)
def test_each_option_sets_what_it_set_over_the_variable(
    monkeypatch, name: str, env_text: str, cli_text: str, cli_value
) -> None:
    import service.app
    import service.cli

    captured: list[Any] = []

    def create_app(settings: Any) -> None:
        captured.append(settings)
        raise ValueError("captured")  # serve prints it and exits: nothing is built

    monkeypatch.setattr(service.app, "create_app", create_app)
    monkeypatch.setattr(service.cli, "_check_port_free", lambda host, port: None)
    args = ["serve", *_flag(name, cli_text)]
    for other, text in NEEDS.get(name, {}).items():
        args += _flag(other, text)
    env = {f"ARMFLEET_{name.upper()}": _here(env_text)}
    result = CliRunner().invoke(app, args, env=env)
    assert captured, result.output
    assert _read(captured[0], name) == _here(cli_value)


def test_unset_everything_is_the_default() -> None:
    from service.settings import Settings

    settings = Settings()
    assert {name: _read(settings, name) for name in DEFAULTS} == DEFAULTS


@pytest.mark.parametrize(("name", "env_text", "env_value"), [r[:3] for r in VALUES])
def test_each_flat_keyword_sets_what_it_set(name: str, env_text: str, env_value) -> None:
    """`Settings(worlds=4, foxglove=True)`: tests and bench build settings by flat names."""
    from service.settings import Settings

    value = [env_text[2:-2]] if name == "allow_origins" else _here(env_text)
    settings = Settings(**{name: value}, **NEEDS.get(name, {}))
    assert _read(settings, name) == _here(env_value)
