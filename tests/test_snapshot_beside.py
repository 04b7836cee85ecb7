"""The loop's periodic snapshot copied beside the next tick (service/core/sim/snapshot_beside.py).

A real WorldBatch on Warp's CPU device, with `copies_beside` turned on (on a GPU it is on by
itself; on the CPU the copy is made at once, so the loop's order is what is checked here): the
snapshot taken beside equals the plain one of the same tick and stays so while later ticks run;
in the loop, every snapshot reaches the sinks in tick order, the periodic ones go the beside
way, readers still get the tick they wait for, and a pause shows the tick it stopped at.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import wait_for

from service.core.sim.batch import SnapshotsBeside
from service.core.sim.loop import SimLoop
from service.core.sim.loop_types import SnapshotSink
from service.core.sim.types import Mode, Snapshot
from service.engines.warp import WorldBatch


@pytest.fixture(scope="module")
def batch():
    b = WorldBatch(3)
    b.copies_beside = True
    yield b
    b.close()


def _fields(snap: Snapshot) -> dict[str, np.ndarray]:
    return {
        f.name: np.array(getattr(snap, f.name))
        for f in dataclasses.fields(snap)
        if isinstance(getattr(snap, f.name), np.ndarray)
    } | {"body_pos": np.array(snap.body_pos), "flange_pos": np.array(snap.flange_pos)}


def test_a_snapshot_copied_beside_is_the_plain_one_of_its_tick(batch) -> None:
    assert isinstance(batch, SnapshotsBeside)
    batch.apply_targets(np.array([1]), np.full((1, 7), 0.3))
    batch.step(3)
    got = batch.snapshot_beside()
    assert got is not None
    beside, wait = got
    plain = batch.snapshot()
    batch.step(2)  # later ticks do not reach a snapshot already on its way
    wait()
    assert beside.tick == plain.tick == batch.tick - 2
    want = _fields(plain)
    have = _fields(beside)
    assert want.keys() == have.keys()
    for name, value in want.items():
        np.testing.assert_array_equal(have[name], value, err_msg=name)
    batch.copies_beside = False
    assert batch.snapshot_beside() is None  # the engine says when it gains nothing: plain then
    batch.copies_beside = True


class _Ticks(SnapshotSink):
    def __init__(self) -> None:
        self.ticks: list[int] = []

    def publish(self, snapshot: Snapshot) -> None:
        self.ticks.append(snapshot.tick)


def test_the_loop_shows_periodic_snapshots_in_order_and_readers_get_their_tick(batch) -> None:
    sink = _Ticks()
    started = []
    real = batch.snapshot_beside

    def counted():
        started.append(batch.tick)
        return real()

    batch.snapshot_beside = counted
    loop = SimLoop(batch, Mode.FAST, sinks=(sink,))
    loop.start()
    try:
        wait_for(lambda: len(started) >= 3, "three periodic snapshots copied beside")
        need = loop.tick
        assert loop.fresh_snapshot().result(timeout=10).tick >= need
        loop.set_mode(Mode.PAUSED)
        stopped = loop.step(1).result(timeout=10)  # at rest after this tick
        assert loop.fresh_snapshot().result(timeout=10).tick == stopped == loop.latest.tick
    finally:
        loop.stop()
        del batch.snapshot_beside
    shown = sink.ticks
    assert shown == sorted(shown) and len(set(shown)) == len(shown)  # in order, each once
    assert set(started) <= set(shown)  # every snapshot started beside was shown
    assert shown[-1] == stopped
