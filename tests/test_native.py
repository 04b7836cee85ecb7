"""`armfleet serve --engine mujoco`: the native engine behind the real service, over sockets.

The engine's behaviour (targets, resets, faults, grasp, fidelity) is tested with the warp
engine's in tests/test_engine.py; this checks that the service runs it end to end.
"""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest
from conftest import ELBOW, HOME, serve, wait_for
from websockets.sync.client import connect

from service.native import NativeBatch, usable_cores


def test_native_batch_uses_every_usable_core_by_default():
    batch = NativeBatch(8)
    assert batch.nthread == min(8, usable_cores())
    assert NativeBatch(8, nthread=1).nthread == 1
    assert NativeBatch(1, nthread=4).nthread == 1  # no more threads than worlds


def test_native_engine_refuses_a_gpu_device():
    with pytest.raises(ValueError, match="CPU only"):
        NativeBatch(1, device="cuda")


def test_service_runs_the_native_engine_end_to_end(tmp_path):
    with serve(worlds=4, extra_args=("--engine", "mujoco"), log_dir=tmp_path) as srv:
        http = httpx.Client(base_url=srv.url, timeout=10)
        info = http.get("/v1/info").json()
        assert "native MuJoCo" in info["device"]
        assert info["substeps"] * info["physics_dt"] == pytest.approx(1 / 60)

        with connect(f"{srv.ws_url}/v1/ws/worlds/3?rate=30") as ws:
            ws.send('{"op": "increment", "joint": "elbow_joint", "delta": 0.2, "id": 1}')
            ack = wait_for(lambda: _next_ack(ws), "the increment's ack")
            assert ack["target"][ELBOW] == pytest.approx(HOME[ELBOW] + 0.2)

        def moved() -> bool:
            position = http.get("/v1/worlds/3/state").json()["position"]
            return abs(position[ELBOW] - (HOME[ELBOW] + 0.2)) < 0.01

        wait_for(moved, "world 3's elbow to reach its new target")
        states = http.get("/v1/worlds/state").json()["worlds"]
        others = np.array([s["position"][ELBOW] for s in states[:3]])
        np.testing.assert_allclose(others, HOME[ELBOW], atol=1e-3)  # the others did not move
        assert all(s["faults"] == 0 for s in states)

        http.post("/v1/worlds/3/reset").raise_for_status()
        wait_for(
            lambda: http.get("/v1/worlds/3/state").json()["target"][ELBOW] == HOME[ELBOW],
            "world 3's reset",
        )


def _next_ack(ws) -> dict | None:
    msg = json.loads(ws.recv(timeout=5))
    return msg if msg.get("op") == "ack" else None
