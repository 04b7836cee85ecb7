"""ShardedBatch: worlds split across processes behave exactly like one WorldBatch.

A server serving worlds on a worker shard: tests/test_faults.py, on the sharded server whose
worker it then kills (one MuJoCo Warp server and worker for both).
"""

from __future__ import annotations

import numpy as np
import pytest

from service.engines.shards import ShardedBatch, auto_shards
from service.engines.warp import WorldBatch

NWORLD = 6


@pytest.fixture(scope="module")
def pair():
    sharded = ShardedBatch(NWORLD, shards=2)
    single = WorldBatch(NWORLD)
    yield sharded, single
    sharded.close()


def _drive_alike(batches, seed: int, ticks: int, k: int, step: int, resets: list[int]) -> None:
    """The same random targets for k worlds a tick into every batch, `resets` reset halfway."""
    rng = np.random.default_rng(seed)
    for tick in range(ticks):
        worlds = rng.choice(NWORLD, size=k, replace=False)
        targets = batches[0].home_target + rng.uniform(-0.3, 0.3, size=(k, 7))
        for b in batches:
            if tick == ticks // 2:
                b.reset(np.array(resets))
            b.apply_targets(worlds, targets)
            b.step(step)


def test_sharded_worlds_step_bit_identically_to_one_batch(pair):
    sharded, single = pair
    _drive_alike(pair, seed=5, ticks=40, k=3, step=1, resets=[1, 4])  # 3 worlds span both shards
    np.testing.assert_array_equal(sharded.qpos(), single.qpos())
    asked = np.array([5, 0, 3, 4])  # both shards, out of order: rows come back as asked
    np.testing.assert_array_equal(sharded.render_state(asked), single.qpos()[asked])
    a, b = sharded.snapshot(), single.snapshot()
    assert a.tick == b.tick == 40
    fields = ("position", "velocity", "effort", "target", "flange_pos", "sim_time", "body_pos")
    for field in (*fields, "body_quat"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_reset_after_targets_in_the_same_tick_wins_on_a_worker_shard(pair):
    sharded, _ = pair
    sharded.apply_targets(np.array([5]), sharded.home_target[None] + 0.2)
    sharded.reset(np.array([5]))
    sharded.step(1)
    np.testing.assert_allclose(sharded.snapshot().target[5], sharded.home_target)


def test_an_engine_kept_apart_steps_bit_identically_to_one_batch_in_this_process():
    """local=False: every shard a worker (the engine when the cameras have a GPU of their own)."""
    apart, single = ShardedBatch(NWORLD, shards=2, local=False), WorldBatch(NWORLD)
    try:
        assert not apart.health() and apart.spec == single.spec
        _drive_alike((apart, single), seed=9, ticks=12, k=2, step=2, resets=[0, 5])
        np.testing.assert_array_equal(apart.qpos(), single.qpos())
        np.testing.assert_array_equal(apart.render_state(np.array([4, 1])), single.qpos()[[4, 1]])
        a, b = apart.snapshot(), single.snapshot()
        assert a.tick == b.tick == apart.tick == 24
        np.testing.assert_array_equal(a.position, b.position)
        state = apart.get_state()
        assert state.tick == 24
        apart.step(3)
        apart.set_state(state)  # back in time: the count comes back with the state
        assert apart.tick == 24
        np.testing.assert_array_equal(apart.qpos(), single.qpos())
    finally:
        apart.close()


def test_auto_shards_uses_cores_only_for_big_cpu_batches():
    assert auto_shards(1, "cpu") == 1
    assert auto_shards(4096, "cuda") == 1
    assert auto_shards(4096, "cpu") >= 1
