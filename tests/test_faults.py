"""Faults survived: a shard worker killed with SIGKILL, and an engine that raises.

A real sharded server (worlds 2..3 on a worker process) first serves commands and states as it
should, then has its worker killed: the service notices, tells its subscribers, rebuilds the
shard and puts its worlds back, while the other shard's worlds keep running. One server for
both tests (a MuJoCo Warp server and its worker cost about 11 s of CPU to start); the kill
comes last. The last test wraps a real WorldBatch whose step raises for a while (fault
injection, not a stand-in for the engine) to check the loop reports it once and recovers.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import threading
import time

import httpx
import numpy as np
import psutil
import pytest
from conftest import serve, wait_for
from websockets.sync.client import connect

from service.core.sim.loop import SimLoop
from service.core.sim.types import Mode
from service.engines.warp import WorldBatch


def _shard_workers(pid: int) -> list[psutil.Process]:
    """The server's shard worker processes (spawned children, not the resource tracker)."""
    kids = psutil.Process(pid).children(recursive=True)
    return [p for p in kids if "spawn_main" in " ".join(p.cmdline())]


@pytest.fixture(scope="module")
def sharded(tmp_path_factory: pytest.TempPathFactory):
    """4 warp worlds on 2 shards, worlds 2..3 on a worker process (realtime, as served)."""
    log_dir = tmp_path_factory.mktemp("sharded")
    with serve(worlds=4, extra_args=("--engine", "warp", "--shards", "2"), log_dir=log_dir) as srv:
        yield srv


def test_service_serves_worlds_on_a_worker_shard(sharded):
    http = httpx.Client(base_url=sharded.url, timeout=10)
    assert http.get("/v1/info").json()["shards"] == 2
    r = http.post("/v1/worlds/3/increments", json={"joint": "elbow_joint", "delta": 0.2})
    target, at = r.json()["target"], r.json()["tick"]
    # a second of simulated time after the command (not a 1 s sleep: fewer ticks when a
    # loaded box's real-time loop gives time up)
    wait_for(lambda: http.get("/v1/info").json()["tick"] >= at + 60, "a second of ticks", 60)
    states = http.get("/v1/worlds/state").json()["worlds"]
    assert states[3]["position"][2] == pytest.approx(target[2], abs=0.01)
    assert states[0]["target"][2] == pytest.approx(1.57)
    http.post("/v1/worlds/3/reset").raise_for_status()
    wait_for(
        lambda: http.get("/v1/worlds/3/state").json()["target"][2] == pytest.approx(1.57),
        "world 3's reset to show",
        60,
    )


def test_a_killed_shard_worker_is_noticed_rebuilt_and_its_worlds_restored(sharded):
    srv = sharded
    http = httpx.Client(base_url=srv.url, timeout=10)
    assert http.get("/v1/info").json()["shards"] == 2
    moved = http.put("/v1/worlds/3/targets", json={"name": ["elbow_joint"], "position": [1.2]})
    assert http.get("/v1/worlds/3/state").json()["target"][2] == pytest.approx(1.2)
    statuses: list[dict] = []
    watching = threading.Event()

    def watch() -> None:
        with connect(f"{srv.ws_url}/v1/ws/worlds/0?rate=2") as ws:
            watching.set()
            while len(statuses) < 2:
                msg = json.loads(ws.recv(timeout=180))
                if msg["op"] == "status":
                    statuses.append(msg)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    assert watching.wait(60), "the status watcher never connected"
    # Long enough for a state copy of the worker's shard (taken every couple of seconds).
    wait_for(lambda: http.get("/v1/worlds/3/state").json()["sim_time"] > 4.0, "4 s simulated", 120)
    (worker,) = _shard_workers(srv.process.pid)
    t0 = time.monotonic()
    os.kill(worker.pid, signal.SIGKILL)

    def not_ready() -> dict | None:
        r = http.get("/readyz")
        return r.json() if r.status_code == 503 else None

    down = wait_for(not_ready, "/readyz to report the lost shard", timeout=10)
    noticed = time.monotonic() - t0
    assert "shard 1" in down["detail"] and "worlds 2..3" in down["detail"]
    assert "signal 9" in down["detail"]

    # The other shard's worlds keep running meanwhile, commands included.
    tick0 = http.get("/v1/info").json()["tick"]
    r = http.post("/v1/worlds/0/increments", json={"joint": "elbow_joint", "delta": 0.1})
    assert http.get("/v1/worlds/0/state").json()["target"][2] == pytest.approx(1.67)
    wait_for(lambda: http.get("/v1/info").json()["tick"] > tick0 + 10, "ticks to go on")
    assert r.status_code == 200

    wait_for(lambda: http.get("/readyz").status_code == 200, "the shard rebuilt", timeout=240)
    recovered = time.monotonic() - t0
    watcher.join(30)
    assert [s["ready"] for s in statuses] == [False, True], statuses
    assert "shard 1" in statuses[0]["problems"][0]

    # Its worlds are back from their last state copy (not from home: their simulated time
    # goes on from seconds in), with the commanded targets; the loss counts as a fault.
    s3 = http.get("/v1/worlds/3/state").json()
    assert s3["target"][2] == pytest.approx(1.2) and s3["faults"] == 1
    assert s3["sim_time"] > 2.0
    assert moved.status_code == 200
    wait_for(
        lambda: abs(http.get("/v1/worlds/3/state").json()["position"][2] - 1.2) < 0.05,
        "world 3 to drive back to its target",
        timeout=30,
    )
    metrics = http.get("/metrics").text
    assert "armfleet_shard_restarts_total 1.0" in metrics
    (new_worker,) = _shard_workers(srv.process.pid)
    assert new_worker.pid != worker.pid
    log = srv.log()
    assert log.count("lost: killed by signal 9") <= 2  # the loss is logged, not every tick
    assert "tick failed" not in log and "resume from its state copy" in log
    print(f"killed worker noticed after {noticed:.2f} s, ready again after {recovered:.1f} s")


class _FailingFor:
    """A real WorldBatch whose step raises while `failing` is set (fault injection)."""

    def __init__(self, batch: WorldBatch) -> None:
        self._batch = batch
        self.failing = threading.Event()

    def __getattr__(self, name: str):
        return getattr(self._batch, name)

    def step(self, ticks: int = 1) -> np.ndarray:
        if self.failing.is_set():
            raise RuntimeError("injected engine failure")
        return self._batch.step(ticks)


def test_an_engine_exception_is_logged_once_and_marks_the_loop_failed(caplog):
    batch = _FailingFor(WorldBatch(1))
    loop = SimLoop(batch, Mode.FAST)  # type: ignore[arg-type]
    caplog.set_level(logging.INFO, logger="armfleet.loop")
    loop.start()
    try:
        wait_for(lambda: loop.tick > 5, "ticks")
        batch.failing.set()
        wait_for(lambda: loop.failure is not None, "the failure to show")
        time.sleep(1.0)  # ~10 more failing attempts
        errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
        assert len(errors) == 1 and errors[0].exc_info is not None
        assert "injected engine failure" in loop.failure
        frozen = loop.tick
        batch.failing.clear()
        wait_for(lambda: loop.failure is None and loop.tick > frozen, "recovery")
        assert any("succeed again" in r.getMessage() for r in caplog.records)
    finally:
        loop.stop()
        batch.close()
