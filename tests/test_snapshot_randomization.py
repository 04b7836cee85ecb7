"""Snapshots name each world's last randomisation (seed and spec), restores keep it.

Real servers over real sockets, paused on native MuJoCo (float64: the JSON of a state is its
bits): worlds 0-3 are randomised with a seed, a snapshot names that seed and spec for exactly
those worlds (in the listing, the route's reply and the file's own header; a paused server
applies a randomisation at once, so one accepted after the last step is in the state and in the
header, with the tick it will be stepped from), and a fresh
server restored from the file holds the same state bit for bit, steps on identically, and still
names the seed and spec, in the snapshots it takes and per world. A file of the previous format
(/1, no randomisation in its header) still loads, its worlds with none.
"""

from __future__ import annotations

import asyncio
import io
import json
import shutil
from pathlib import Path

import httpx
import numpy as np
import pytest

from bench.cells import SPEC
from clients import ArmfleetClient, AsyncArmfleetClient
from clients.testing import serve

NWORLD = 6
SEED = 11


def _server(tmp: Path, *extra: str):
    tmp.mkdir(parents=True, exist_ok=True)
    args = ("--engine", "mujoco", "--data-dir", str(tmp / "data"), *extra)
    return serve(worlds=NWORLD, mode="paused", extra_args=args, log_dir=tmp)


def _everything(http: httpx.Client) -> dict:
    """Every world's joints, entities and parameters, as JSON (float64 text: exact)."""
    states = http.get("/v1/worlds/state", params={"entities": "true"}).json()
    params = [http.get(f"/v1/worlds/{w}/params").json()["params"] for w in range(NWORLD)]
    return {"states": states, "params": params}


def _header(path: Path) -> dict:
    with np.load(path) as npz:
        return json.loads(npz["header"].tobytes())


def test_a_snapshot_names_the_seed_and_spec_and_a_restore_keeps_them(tmp_path):
    a_dir, b_dir = tmp_path / "a", tmp_path / "b"
    expected = None
    with _server(a_dir) as a:
        http = httpx.Client(base_url=a.url, timeout=30)
        http.post("/v1/sim/step", json={"ticks": 3}).raise_for_status()
        ack = http.post("/v1/randomize", json={"seed": SEED, "spec": SPEC, "worlds": [0, 1, 2, 3]})
        ack = ack.json()
        http.post("/v1/sim/step", json={"ticks": 10}).raise_for_status()
        # paused: world 4's randomisation is applied at once, before its tick is stepped
        four = http.post("/v1/randomize", json={"seed": 99, "spec": SPEC, "worlds": [4]}).json()
        expected = [
            {"worlds": [0, 1, 2, 3], "tick": ack["tick"], "seed": SEED, "spec": SPEC},
            {"worlds": [4], "tick": four["tick"], "seed": 99, "spec": SPEC},
        ]

        info = http.post("/v1/snapshots", json={"name": "drawn"}).json()
        assert info["format"] == "armfleet-snapshot/2"
        assert info["randomization"] == expected
        assert http.get("/v1/snapshots").json()[0]["randomization"] == expected
        path = a_dir / "data" / "snapshots" / "drawn.npz"
        assert _header(path)["randomization"] == expected
        # the snapshot holds the state of its tick, world 4's draw in it already
        state_before = _everything(http)
        assert state_before["states"]["tick"] == info["tick"] == four["tick"] - 1
        one = http.get("/v1/worlds/2/randomization").json()
        assert (one["seed"], one["spec"], one["randomized_at"]) == (SEED, SPEC, ack["tick"])
        http.post("/v1/sim/step", json={"ticks": 20}).raise_for_status()
        after_a = _everything(http)
        assert http.get("/v1/worlds/4/randomization").json()["seed"] == 99

    (b_dir / "data" / "snapshots").mkdir(parents=True)
    shutil.copy(path, b_dir / "data" / "snapshots" / "drawn.npz")
    with _server(b_dir) as b:
        http = httpx.Client(base_url=b.url, timeout=30)
        assert http.get("/v1/worlds/2/randomization").json()["seed"] is None  # fresh: none
        listed = http.get("/v1/snapshots").json()
        assert [(i["name"], i["randomization"]) for i in listed] == [("drawn", expected)]
        assert http.post("/v1/snapshots/drawn/restore").json()["tick"] == info["tick"]
        assert _everything(http) == state_before  # bit for bit (float64 JSON round-trips)
        for w in range(NWORLD):
            got = http.get(f"/v1/worlds/{w}/randomization").json()
            want = {4: (99, SPEC), 5: (None, None)}.get(w, (SEED, SPEC))
            assert (got["seed"], got["spec"]) == want
        # a snapshot of the restored worlds still names the seed and spec
        again = http.post("/v1/snapshots", json={"name": "again"}).json()
        assert again["randomization"] == expected
        # and they step on identically, world 4's draw included
        http.post("/v1/sim/step", json={"ticks": 20}).raise_for_status()
        assert _everything(http) == after_a


def test_a_previous_format_file_still_loads_with_no_randomisation(tmp_path):
    with _server(tmp_path) as srv:
        http = httpx.Client(base_url=srv.url, timeout=30)
        http.post("/v1/randomize", json={"seed": SEED, "spec": SPEC}).raise_for_status()
        http.post("/v1/sim/step", json={"ticks": 2}).raise_for_status()
        http.post("/v1/snapshots", json={"name": "new"}).raise_for_status()
        snaps = tmp_path / "data" / "snapshots"
        # the same file as the previous format wrote it: format /1, no `randomization`
        with np.load(snaps / "new.npz") as npz:
            arrays = {k: npz[k] for k in npz.files}
        header = json.loads(arrays.pop("header").tobytes())
        header["format"] = "armfleet-snapshot/1"
        del header["randomization"]
        buf = io.BytesIO()
        head = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
        np.savez(buf, header=head, **arrays)
        (snaps / "old.npz").write_bytes(buf.getvalue())
        listed = {i["name"]: i for i in http.get("/v1/snapshots").json()}
        assert listed["old"]["format"] == "armfleet-snapshot/1"
        assert listed["old"]["randomization"] == []
        before = _everything(http)
        http.post("/v1/sim/step", json={"ticks": 5}).raise_for_status()
        assert http.get("/v1/worlds/1/randomization").json()["seed"] == SEED
        assert http.post("/v1/snapshots/old/restore").status_code == 200
        assert _everything(http) == before
        assert http.get("/v1/worlds/1/randomization").json()["seed"] is None
        # a header naming a world that does not exist is refused, and nothing changes
        header = {**header, "format": "armfleet-snapshot/2"}
        header["randomization"] = [{"worlds": [NWORLD], "tick": 1, "seed": 1, "spec": {}}]
        buf = io.BytesIO()
        head = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
        np.savez(buf, header=head, **arrays)
        (snaps / "bad.npz").write_bytes(buf.getvalue())
        reply = http.post("/v1/snapshots/bad/restore")
        assert reply.status_code == 409 and "randomization.0" in reply.text
        assert _everything(http) == before


@pytest.mark.parametrize("name", ["drawn"])
def test_restore_at_start_keeps_the_randomisation(tmp_path, name):
    with _server(tmp_path) as srv, ArmfleetClient(srv.url) as arm:
        ack = arm.randomize(SEED, SPEC, [3])
        assert (ack["seed"], ack["worlds"]) == (SEED, [3])
        arm.step(1)
        http = httpx.Client(base_url=srv.url, timeout=30)
        http.post("/v1/snapshots", json={"name": name}).raise_for_status()
    with _server(tmp_path, "--restore", name) as srv:
        with ArmfleetClient(srv.url) as arm:
            got = arm.randomization(3)
            assert (got["seed"], got["spec"], got["randomized_at"]) == (SEED, SPEC, ack["tick"])
            assert arm.randomization(2)["seed"] is None

        async def read() -> dict:
            async with AsyncArmfleetClient(srv.url) as arm:
                return await arm.randomization(3)

        assert asyncio.run(read())["seed"] == SEED
