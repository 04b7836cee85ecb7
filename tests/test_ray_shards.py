"""RayBatch: shards on Ray actors behave exactly like one WorldBatch, and survive a lost actor.

One local Ray instance (bound to 127.0.0.1, no dashboard; stopped after this module's tests), one
RayBatch of two CPU actors and one in-process WorldBatch of the same worlds as the reference.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from conftest import local_ray

ray = pytest.importorskip("ray")

from ray.exceptions import RayActorError  # noqa: E402

from service.engines.ray_shards import RayBatch  # noqa: E402
from service.engines.sharding import join_states, slice_state  # noqa: E402
from service.engines.warp import WorldBatch  # noqa: E402

NWORLD = 6
FIELDS = ("position", "velocity", "effort", "target", "flange_pos", "flange_quat", "sim_time")
# A rebuilt actor loads every kernel again; on a busy 2-core machine that can take a while.
REBUILD_DEADLINE_S = 300


@pytest.fixture(scope="module")
def pair():
    with local_ray():
        sharded = RayBatch(NWORLD, shards=2, checkpoint_s=math.inf)  # the restore test turns it on
        single = WorldBatch(NWORLD)
        yield sharded, single
        sharded.close()


def drive(pair, rng, ticks: int) -> None:
    """The same random commands and resets into both batches, tick by tick."""
    sharded, single = pair
    for tick in range(ticks):
        worlds = rng.choice(NWORLD, size=3, replace=False)  # spans both shards
        targets = single.home_target + rng.uniform(-0.3, 0.3, size=(3, 7))
        for b in pair:
            if tick % 15 == 7:
                b.reset(np.array([1, 4]))
            b.apply_targets(worlds, targets)
        assert sharded.step(1).size == 0
        single.step(1)


def assert_identical(sharded, single) -> None:
    np.testing.assert_array_equal(sharded.qpos(), single.qpos())
    np.testing.assert_array_equal(sharded.qvel(), single.qvel())
    a, b = sharded.snapshot(), single.snapshot()
    assert a.tick == b.tick
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


def test_ray_shards_step_bit_identically_to_one_batch(pair):
    sharded, single = pair
    assert sharded.shards == 2 and sharded.nworld == NWORLD
    assert sharded.device_name.startswith("ray")
    drive(pair, np.random.default_rng(5), 40)
    assert sharded.tick == single.tick == 40
    assert_identical(sharded, single)


def test_snapshots_asked_every_tick_or_every_other_are_those_of_one_batch(pair):
    """These cadences are prefetched with the step (see RayBatch._snapshot_expected)."""
    sharded, single = pair
    prefetched = sharded.prefetched
    rng = np.random.default_rng(11)
    for tick in range(24):
        targets = single.home_target + rng.uniform(-0.2, 0.2, size=(NWORLD, 7))
        for b in pair:
            b.apply_targets(np.arange(NWORLD), targets)
            b.step(1)
        if tick < 12 or tick % 2:
            a, b = sharded.snapshot(), single.snapshot()
            assert a.tick == b.tick
            for f in FIELDS + ("body_pos", "body_quat"):
                np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    assert sharded.prefetched - prefetched >= 15  # all but the first of each cadence
    assert_identical(sharded, single)


def test_reset_after_targets_in_the_same_tick_wins(pair):
    sharded, single = pair
    for b in pair:
        b.apply_targets(np.array([5]), b.home_target[None] + 0.2)
        b.reset(np.array([5]))
        b.step(1)
    np.testing.assert_array_equal(sharded.snapshot().target[5], sharded.home_target)
    assert_identical(sharded, single)


def kill(batch: RayBatch, shard: int) -> None:
    """ray.kill, then wait until calls on the actor fail (ray.kill is asynchronous)."""
    victim = batch.actors[shard]
    ray.kill(victim, no_restart=True)
    deadline = time.monotonic() + REBUILD_DEADLINE_S
    while True:
        try:
            ray.get(victim.snapshot.remote())
        except RayActorError:
            return
        assert time.monotonic() < deadline, "ray.kill did not kill the actor"
        time.sleep(0.05)


def test_a_killed_actor_is_rebuilt_and_its_worlds_come_back_at_home(pair):
    sharded, single = pair
    drive(pair, np.random.default_rng(7), 5)
    lost_worlds = np.arange(3, 6)  # shard 1
    kill(sharded, 1)
    deadline = time.monotonic() + REBUILD_DEADLINE_S
    before = sharded.snapshot()  # notices the loss: shard 1 shows its last state from now on
    assert sharded.rebuilds == 1

    # The other shard keeps stepping while the lost one is rebuilt; commands still go in.
    while True:
        for b in pair:
            b.apply_targets(np.array([0, 4]), b.home_target[None] + 0.05)
        back = sharded.step(1)
        if back.size:
            np.testing.assert_array_equal(np.sort(back), lost_worlds)
            single.reset(back)  # what happened to those worlds: home, at this tick
            single.step(1)
            break
        single.step(1)
        frozen = sharded.snapshot()
        np.testing.assert_array_equal(frozen.position[3:], before.position[3:])
        assert time.monotonic() < deadline, "the lost shard was not rebuilt"
        time.sleep(0.05)

    assert sharded.rebuilds == 1
    snap = sharded.snapshot()
    np.testing.assert_array_equal(snap.target[lost_worlds], np.tile(sharded.home_target, (3, 1)))
    np.testing.assert_array_equal(snap.faults, [0, 0, 0, 1, 1, 1])
    assert_identical(sharded, single)  # shard 0 never noticed; shard 1 is home + one tick
    drive(pair, np.random.default_rng(9), 10)  # and both shards go on in lockstep
    assert_identical(sharded, single)


def test_a_killed_actor_resumes_from_its_last_checkpoint_with_todays_targets(pair):
    """With checkpoints on, the lost worlds continue from the last copied state, bit-exactly."""
    sharded, single = pair
    sharded.checkpoint_s = 0.0  # a copy after every step
    rng = np.random.default_rng(13)
    history = {}  # the reference's state at each tick boundary
    for _ in range(8):  # long enough for copies to arrive
        history[single.tick] = single.get_state()
        drive(pair, rng, 1)
    assert sharded._shards[1].checkpoint is not None
    restored = len(sharded.restored)
    kill(sharded, 1)
    sharded.snapshot()  # notices the loss
    deadline = time.monotonic() + REBUILD_DEADLINE_S
    while True:
        targets = single.home_target + rng.uniform(-0.2, 0.2, size=(NWORLD, 7))
        for b in pair:
            b.apply_targets(np.arange(NWORLD), targets)
        now = single.get_state()
        history[single.tick] = now
        assert sharded.step(1).size == 0  # resumed worlds are not faults
        if len(sharded.restored) > restored:
            shard, tick = sharded.restored[-1]
            assert shard == 1 and tick < single.tick
            # What the reference must do: worlds 3..5 back to that tick, today's targets.
            back = slice_state(history[tick], 3, NWORLD)
            physics = dict(back.physics)
            physics["ctrl"] = slice_state(now, 3, NWORLD).physics["ctrl"]
            back = dataclasses.replace(back, physics=physics)
            joined = join_states([slice_state(now, 0, 3), back], now.targets)
            single.set_state(dataclasses.replace(joined, tick=now.tick, faults=now.faults))
            single.step(1)
            break
        single.step(1)
        assert time.monotonic() < deadline, "the lost shard was not rebuilt"
        time.sleep(0.05)
    sharded.checkpoint_s = math.inf
    assert_identical(sharded, single)
    drive(pair, rng, 5)
    assert_identical(sharded, single)


def test_state_round_trips_through_the_ray_shards(pair):
    sharded, single = pair
    state = sharded.get_state()
    ref = single.get_state()
    assert state.tick == sharded.tick
    np.testing.assert_array_equal(state.targets, ref.targets)
    for name, arr in ref.physics.items():
        np.testing.assert_array_equal(state.physics[name], arr, err_msg=name)
    drive(pair, np.random.default_rng(17), 4)
    sharded.set_state(state)
    single.set_state(ref)
    assert sharded.tick == state.tick
    drive(pair, np.random.default_rng(19), 4)
    assert_identical(sharded, single)
