"""The engine in a worker process of its own (`--engine-worker`, and what `--camera-device` on
another device implies): a real server whose warp engine steps in a spawned process.

The cameras draw in the server's process from the states the worker hands over, the worlds obey
commands as before, and killing the engine's process leaves the server up: it says so, rebuilds
the engine from its last state copy, and the worlds and their pictures come back.
"""

from __future__ import annotations

import io
import os
import signal

import httpx
import numpy as np
import psutil
import pytest
from conftest import wait_for
from PIL import Image

from clients.testing import serve

CAMERAS = ("--camera-size", "64x48", "--cameras", "overview=off")


def _workers(pid: int) -> list[psutil.Process]:
    """The server's engine worker processes (spawned children, not the resource tracker)."""
    kids = psutil.Process(pid).children(recursive=True)
    return [p for p in kids if "spawn_main" in " ".join(p.cmdline())]


def _wrist(http: httpx.Client, world: int) -> np.ndarray:
    r = http.get(f"/v1/worlds/{world}/cameras/wrist", timeout=120)
    r.raise_for_status()
    return np.asarray(Image.open(io.BytesIO(r.content)).convert("RGB"), dtype=np.int16)


def test_an_engine_in_its_own_process_serves_commands_pictures_and_survives_a_kill(tmp_path):
    args = ("--engine", "warp", "--engine-worker", *CAMERAS)
    with serve(worlds=2, extra_args=args, log_dir=tmp_path) as srv:
        http = httpx.Client(base_url=srv.url, timeout=30)
        (worker,) = _workers(srv.process.pid)
        wait_for(lambda: http.get("/v1/cameras").json()["ready"], "cameras", 300)
        before = _wrist(http, 1)
        np.testing.assert_array_equal(before, _wrist(http, 0))  # both at home: same picture
        moved = http.put(
            "/v1/worlds/1/targets", json={"name": ["wrist_1_joint"], "position": [-0.6]}
        )
        moved.raise_for_status()
        wait_for(
            lambda: abs(http.get("/v1/worlds/1/state").json()["position"][3] + 0.6) < 0.02,
            "world 1 to reach its target",
            timeout=30,
        )
        assert np.abs(_wrist(http, 1) - before).mean() > 2.0  # the wrist camera moved with it
        np.testing.assert_array_equal(_wrist(http, 0), before)  # world 0 did not
        # Long enough for a state copy of the engine's worlds (taken every couple of seconds).
        wait_for(lambda: http.get("/v1/worlds/1/state").json()["sim_time"] > 4.0, "4 s simulated")

        os.kill(worker.pid, signal.SIGKILL)
        down = wait_for(
            lambda: (r := http.get("/readyz")).status_code == 503 and r.json(),
            "/readyz to report the lost engine",
        )
        assert "shard 0 (worlds 0..1) lost" in down["detail"] and "signal 9" in down["detail"]
        assert http.get("/healthz").status_code == 200  # the server itself is up meanwhile
        wait_for(lambda: http.get("/readyz").status_code == 200, "the engine rebuilt", 240)
        (new_worker,) = _workers(srv.process.pid)
        assert new_worker.pid != worker.pid
        s1 = http.get("/v1/worlds/1/state").json()
        assert s1["sim_time"] > 2.0 and s1["faults"] == 1  # from its copy, the loss counted
        assert s1["target"][3] == pytest.approx(-0.6)
        tick = http.get("/v1/info").json()["tick"]
        wait_for(lambda: http.get("/v1/info").json()["tick"] > tick + 10, "ticks to go on")
        wait_for(
            lambda: abs(http.get("/v1/worlds/1/state").json()["position"][3] + 0.6) < 0.02,
            "world 1 back at its target",
            timeout=30,
        )
        assert np.abs(_wrist(http, 1) - before).mean() > 2.0  # pictures come from the new one
        assert "tick failed" not in srv.log()


def test_cameras_on_the_engines_own_device_keep_the_engine_in_the_server(hermetic_settings):
    """`--camera-device` naming the engine's device is no reason to move the engine."""
    from service.settings import Settings

    assert not Settings(camera_device="cpu").engine_apart()
    assert Settings(engine_worker=True).engine_apart()
    with pytest.raises(ValueError, match="engine_worker: a worker process holds the warp"):
        Settings(engine="mujoco", engine_worker=True)
    args = ("--engine", "warp", "--camera-device", "cpu", *CAMERAS)
    with serve(worlds=1, extra_args=args) as srv:
        assert _workers(srv.process.pid) == []
        assert httpx.get(f"{srv.url}/v1/info").json()["shards"] == 1
