"""Snapshots: exact restore over the API, refusals that change nothing, save on stop, --restore."""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from conftest import ELBOW, FINGER, Server, running_server
from mcap.reader import make_reader

from clients.testing import stop
from service.core.errors import Conflict
from service.persistence.snapshots import decode_state, encode_state, read_header
from service.runtime import Runtime
from service.settings import Settings

NWORLD = 4


@pytest.fixture(scope="module")
def paused(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, Path]]:
    """A paused 4-world server with its own data directory."""
    tmp = tmp_path_factory.mktemp("snapshots")
    data = tmp / "data"
    with running_server(tmp, worlds=NWORLD, mode="paused", extra=("--data-dir", str(data))) as srv:
        yield srv, data


@pytest.fixture
def http(paused) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=paused[0].url, timeout=30) as client:
        yield client


def everything(http: httpx.Client) -> dict:
    """Every world's full JointState plus targets, faults and tick (floats as sent: exact)."""
    body = http.get("/v1/worlds/state").json()
    return {
        "tick": body["worlds"][0]["tick"],
        "worlds": [
            {k: w[k] for k in ("position", "velocity", "effort", "target", "sim_time", "faults")}
            for w in body["worlds"]
        ],
    }


def drive(http: httpx.Client) -> dict:
    """The same commands and ticks every time: elbow and gripper moves, a reset, 45 ticks."""
    http.post("/v1/worlds/1/increments", json={"joint": "elbow_joint", "delta": 0.3})
    http.put("/v1/worlds/2/targets", json={"name": ["finger_joint"], "position": [0.6]})
    http.post("/v1/sim/step", json={"ticks": 20}).raise_for_status()
    http.post("/v1/worlds/3/reset").raise_for_status()
    http.post("/v1/worlds/0/increments", json={"deltas": {"shoulder_pan_joint": -0.2}})
    http.post("/v1/sim/step", json={"ticks": 25}).raise_for_status()
    return everything(http)


def test_restore_then_the_same_commands_give_bit_identical_states(http):
    http.post("/v1/worlds/1/increments", json={"joint": ELBOW, "delta": -0.2})
    http.post("/v1/sim/step", json={"ticks": 15}).raise_for_status()  # moving when saved
    saved = http.post("/v1/snapshots", json={"name": "exact"})
    assert saved.status_code == 201, saved.text
    assert saved.json()["tick"] == everything(http)["tick"]
    assert saved.json()["nworld"] == NWORLD
    first = drive(http)
    restored = http.post("/v1/snapshots/exact/restore")
    assert restored.status_code == 200, restored.text
    assert restored.json()["tick"] == saved.json()["tick"]
    assert everything(http)["tick"] == saved.json()["tick"]
    second = drive(http)
    assert second == first
    assert first["worlds"][2]["target"][FINGER] == 0.6
    names = [s["name"] for s in http.get("/v1/snapshots").json()]
    assert "exact" in names


def test_the_listing_names_size_tick_world_count_and_model_hash(paused, http):
    # the snapshots guide: `GET /v1/snapshots` gives name, size, tick, nworld, model hash
    _, data = paused
    http.post("/v1/sim/step", json={"ticks": 3}).raise_for_status()
    saved = http.post("/v1/snapshots", json={"name": "listed"})
    assert saved.status_code == 201, saved.text
    (entry,) = [s for s in http.get("/v1/snapshots").json() if s["name"] == "listed"]
    path = data / "snapshots" / "listed.npz"
    assert entry["size_bytes"] == path.stat().st_size
    assert entry["tick"] == saved.json()["tick"] == everything(http)["tick"]
    assert entry["nworld"] == NWORLD
    header = read_header(path.read_bytes())
    assert entry["model_hash"] == header["model_hash"] and len(entry["model_hash"]) == 64
    int(entry["model_hash"], 16)  # hex
    assert entry["format"] == "armfleet-snapshot/2"


@pytest.mark.parametrize("name", ["", "a/b", "../up", ".hidden", "-dash", "x" * 65, "sp ace"])
def test_bad_names_are_refused_with_422(http, name):
    r = http.post("/v1/snapshots", json={"name": name})
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == ["body", "name"]


def test_restore_of_unknown_or_badly_named_snapshot(http):
    assert http.post("/v1/snapshots/never-saved/restore").status_code == 404
    assert http.post("/v1/snapshots/.hidden/restore").status_code == 422


def test_foreign_truncated_or_corrupt_files_get_409_and_change_nothing(paused, http):
    _, data = paused
    assert http.post("/v1/snapshots", json={"name": "good"}).status_code == 201
    raw = (data / "snapshots" / "good.npz").read_bytes()
    header = read_header(raw)
    state = decode_state(raw)
    fewer = dataclasses.replace(
        state,
        world_ticks=state.world_ticks[:2],
        faults=state.faults[:2],
        targets=state.targets[:2],
        physics={k: v[:2] for k, v in state.physics.items()},
    )
    other_model = {**header, "model_hash": "0" * 64}
    files = {
        "two": (encode_state(fewer, {**header, "nworld": 2}), "holds 2 worlds"),
        "model": (encode_state(state, other_model), "another model"),
        "cut": (raw[: len(raw) // 2], "truncated or corrupt"),
        "flip": (raw[:-300] + bytes([raw[-300] ^ 0xFF]) + raw[-299:], "corrupt"),
    }
    http.post("/v1/worlds/1/increments", json={"joint": ELBOW, "delta": 0.1})
    http.post("/v1/sim/step", json={"ticks": 3}).raise_for_status()
    before = everything(http)
    for name, (blob, why) in files.items():
        (data / "snapshots" / f"{name}.npz").write_bytes(blob)
        r = http.post(f"/v1/snapshots/{name}/restore")
        assert r.status_code == 409, (name, r.text)
        assert why in r.json()["detail"], (name, r.json())
    assert everything(http) == before


def test_a_flipped_array_byte_is_caught_by_the_file_checks():
    """Zip CRCs and the digest each catch damage; decode never returns a damaged state."""
    from service.engines.warp import WorldBatch
    from service.persistence.provenance import batch_header

    batch = WorldBatch(2)
    header = batch_header(batch)
    raw = encode_state(batch.get_state(), header, "t")
    assert decode_state(raw, header).tick == 0
    for offset in range(200, len(raw) - 200, max(1, len(raw) // 50)):
        damaged = raw[:offset] + bytes([raw[offset] ^ 0x55]) + raw[offset + 1 :]
        try:
            state = decode_state(damaged, header)
        except Conflict:
            continue
        # Some bytes (zip padding, timestamps) do not matter; the state must then be intact.
        for k, v in batch.get_state().physics.items():
            np.testing.assert_array_equal(state.physics[k], v)


def test_stop_saves_latest_and_restore_latest_starts_from_it(paused, http):
    """Last in the module: it stops the module's server (SIGINT, as Ctrl-C) to see `latest`."""
    srv, data = paused
    http.post("/v1/worlds/1/increments", json={"joint": ELBOW, "delta": -0.4})
    http.post("/v1/sim/step", json={"ticks": 33}).raise_for_status()
    final = everything(http)
    latest = data / "snapshots" / "latest.npz"
    latest.unlink(missing_ok=True)
    assert stop(srv.process) == 0
    assert read_header(latest.read_bytes())["tick"] == final["tick"]  # saved on SIGINT
    run = data / "from-latest.mcap"  # and `serve --record`: the recording starts there too
    extra = ("--data-dir", str(data), "--restore", "latest", "--record", str(run))
    with running_server(data.parent, worlds=NWORLD, mode="paused", extra=extra) as again:
        assert everything(httpx.Client(base_url=again.url, timeout=30)) == final
    with open(run, "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}["armfleet"]
    assert int(meta["start_tick"]) == final["tick"] and int(meta["nworld"]) == NWORLD
    # Another number of worlds: the runtime refuses to start from it and says why (/readyz).
    runtime = Runtime(Settings(worlds=2, data_dir=data, restore="latest", save_on_exit=True))
    asyncio.run(runtime.start())
    assert runtime.loop is None and runtime.error is not None
    assert f"holds {NWORLD} worlds, this service runs 2" in runtime.error
    runtime.stop()
    assert read_header(latest.read_bytes())["nworld"] == NWORLD  # nothing saved over it
