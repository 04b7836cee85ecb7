"""The default engine, served as a user starts it: `armfleet serve` with no engine named steps
MuJoCo Warp on warp's `cpu` device with a captured tick, and a command moves the arm.

The rest of the suite's servers step native MuJoCo unless a test names the engine
(tests/conftest.py says why); this test is the one that starts the service exactly as the README
does, with no `ARMFLEET_ENGINE` in its environment.
"""

from __future__ import annotations

import httpx
import pytest

from tests.conftest import ELBOW, serve, wait_for


def test_a_plain_serve_steps_mujoco_warp_on_the_cpu_and_moves_the_arm(
    monkeypatch: pytest.MonkeyPatch, tmp_path
) -> None:
    monkeypatch.delenv("ARMFLEET_ENGINE", raising=False)
    with serve(worlds=2, log_dir=tmp_path) as srv, httpx.Client(base_url=srv.url) as http:
        info = http.get("/v1/info").json()
        assert info["device"] == "cpu" and info["captured"], info
        before = http.get("/v1/worlds/1/state").json()["position"][ELBOW]
        r = http.post("/v1/worlds/1/increments", json={"joint": "elbow_joint", "delta": 0.2})
        assert r.status_code == 200, r.text

        def moved() -> float | None:
            now = http.get("/v1/worlds/1/state").json()["position"][ELBOW]
            return now if abs(now - before) > 0.1 else None

        wait_for(moved, "world 1's elbow moved by the increment")
        assert abs(http.get("/v1/worlds/0/state").json()["position"][ELBOW] - before) < 1e-3
