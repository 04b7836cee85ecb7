"""`armfleet serve --ray` across two hosts: a Ray head on one, a Ray node on the other.

The hosts are network namespaces joined by a veth pair, made here (bench/ray_hosts.py: Ray on
each bound to its veth address, token authentication on, the API reached from inside the head's
namespace). One shard on each host; commands reach worlds on both and the states are
bit-identical to one WorldBatch stepped with the same commands; killing every process of the
worker host rebuilds its shard on the head from its last state copy while the head's worlds go
on stepping. Needs root and `ip`; skipped with the reason otherwise.

Slow: Ray starts two nodes and two shard actors on a 2-core machine (about a minute in all).
"""

from __future__ import annotations

import re
from collections.abc import Iterator

import numpy as np
import pytest

pytest.importorskip("ray")

from bench.ray_hosts import (
    NsHttp,
    TwoHosts,
    recover,
    serve_flags,
    wait_ready,
    wave,
    why_not,
)
from service.engines.warp import WorldBatch
from service.persistence.snapshots import decode_state

NWORLD = 4


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[TwoHosts, NsHttp]]:
    if why := why_not():
        pytest.skip(why)
    hosts = TwoHosts()
    try:
        hosts.up()
    except Exception as exc:
        hosts.down()
        pytest.skip(f"network namespaces cannot be made here: {exc}")
    log = tmp_path_factory.mktemp("ray_hosts") / "serve.log"
    try:
        hosts.start_ray()
        proc = hosts.serve(log, *serve_flags(hosts, NWORLD))
        http = hosts.http()
        wait_ready(http, proc, log)
        hosts.log = log  # type: ignore[attr-defined]
        yield hosts, http
        http.close()
    finally:
        hosts.down()


@pytest.fixture(scope="module")
def reference() -> WorldBatch:
    return WorldBatch(NWORLD)


def assert_same_state(
    hosts: TwoHosts, http: NsHttp, reference: WorldBatch, name: str, worlds=range(NWORLD)
) -> None:
    """The service's full state (a snapshot file: every physics array, exactly) against the
    reference's, world by world."""
    assert http.post("/v1/snapshots", {"name": name}).status_code == 201
    served = decode_state((hosts.tmp / "data" / "snapshots" / f"{name}.npz").read_bytes())
    ref = reference.get_state()
    assert served.tick == ref.tick
    for field, arr in ref.physics.items():
        for w in worlds:
            np.testing.assert_array_equal(served.physics[field][w], arr[w], err_msg=f"{field} {w}")


def test_ray_listens_only_on_the_hosts_own_addresses(cluster):
    """Ray 2.60 binds its GCS and raylet servers to the wildcard address: inside a host that is
    its loopback and its veth address, nothing else (the namespace is the boundary)."""
    hosts, _ = cluster
    for host in hosts.ns:
        rows = hosts.listeners(host)
        procs = {r["process"] for r in rows}
        assert "raylet" in procs, rows
        allowed = {"*", "0.0.0.0", "127.0.0.1", hosts.ip[host]}
        assert {r["address"] for r in rows} <= allowed, rows
    head = hosts.listeners("head")
    assert any(r["process"] == "gcs_server" and r["port"] == "6379" for r in head), head


def test_commands_reach_worlds_on_both_hosts_bit_identically(cluster, reference):
    hosts, http = cluster
    assert hosts.shard_actors("head") == 1 and hosts.shard_actors("worker") == 1
    assert http.get("/v1/info").json()["shards"] == 2
    h = reference.home_target.tolist()
    for tick in range(0, 90, 15):  # every world's target changes: both shards get commands
        targets = wave(tick, NWORLD, h)
        http.post("/v1/targets", {"worlds": list(range(NWORLD)), "position": targets})
        http.post("/v1/sim/step", {"ticks": 15}).raise_for_status()
        reference.apply_targets(np.arange(NWORLD), np.array(targets))
        reference.step(15)
    assert_same_state(hosts, http, reference, "both")


def test_losing_the_worker_host_rebuilds_its_shard_on_the_head(cluster, reference):
    hosts, http = cluster
    h = reference.home_target.tolist()

    def step_reference(targets: list[list[float]]) -> None:
        reference.apply_targets(np.arange(NWORLD), np.array(targets))
        reference.step(1)

    http.post("/v1/sim/step", {"ticks": 30}).raise_for_status()  # ~0.5 s: state copies arrive
    reference.step(30)
    loss = recover(hosts, http, NWORLD, h, on_step=step_reference)
    assert loss["recovered"], loss
    lost = loss["frozen_worlds"]
    assert lost in ([0, 1], [2, 3]), loss  # exactly one shard's worlds paused meanwhile
    assert loss["other_worlds_moved_every_tick"], loss
    assert loss["ticks_meanwhile"] >= 2
    assert hosts.shard_actors("head") == 2 and hosts.pids("worker") == []
    found = re.search(r"resume from tick (\d+) \(now (\d+)\)", hosts.log.read_text())
    assert found, hosts.log.read_text()[-3000:]
    assert 0 < int(found.group(1)) < int(found.group(2))  # from a copy, not from home
    # The head's worlds never noticed: still bit-identical to the reference.
    assert_same_state(hosts, http, reference, "after", set(range(NWORLD)) - set(lost))
    states = http.get("/v1/worlds/state").json()["worlds"]
    assert [s["faults"] for s in states] == [0] * NWORLD  # resumed, not reset
