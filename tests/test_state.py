"""get_state / set_state beyond the contract test: warm start, refusals, the restored snapshot."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from service.core.sim.types import PHYSICS_FIELDS, BatchState
from service.engines.shards import ShardedBatch
from service.engines.warp import WorldBatch

NWORLD = 4


def drive(batch: WorldBatch | ShardedBatch, ticks: int, seed: int) -> list[np.ndarray]:
    """Random targets (gripper included, so the linkage's constraints work) and a reset midway;
    the full qpos and qvel after every tick."""
    rng = np.random.default_rng(seed)
    out = []
    for t in range(ticks):
        worlds = rng.choice(batch.nworld, size=2, replace=False)
        targets = batch.home_target + rng.uniform(-0.4, 0.4, size=(2, 7))
        targets[:, 6] = rng.uniform(0.0, 0.7, size=2)
        batch.apply_targets(worlds, targets)
        if t == ticks // 2:
            batch.reset(np.array([batch.nworld - 1]))
        batch.step(1)
        out.append(np.concatenate([batch.qpos(), batch.qvel()], axis=1))
    return out


@pytest.fixture(scope="module")
def batch() -> WorldBatch:
    return WorldBatch(NWORLD)


def test_the_solver_warm_start_is_part_of_the_state(batch):
    """Without qacc_warmstart the continuation differs: the test above would catch its loss."""
    drive(batch, 10, seed=3)
    state = batch.get_state()
    first = drive(batch, 5, seed=4)
    cold = dict(state.physics, qacc_warmstart=np.zeros_like(state.physics["qacc_warmstart"]))
    batch.set_state(dataclasses.replace(state, physics=cold))
    again = drive(batch, 5, seed=4)
    assert any(not np.array_equal(a, b) for a, b in zip(first, again, strict=True))


def test_state_holds_every_integration_field_with_documented_shapes(batch):
    state = batch.get_state()
    assert set(state.physics) == set(PHYSICS_FIELDS)
    nq, nv = batch.robot.mjm.nq, batch.robot.mjm.nv
    assert state.physics["qpos"].shape == (NWORLD, nq)
    assert state.physics["qacc_warmstart"].shape == (NWORLD, nv)
    assert state.physics["xfrc_applied"].shape == (NWORLD, batch.robot.mjm.nbody, 6)
    assert state.physics["eq_active"].dtype == bool
    assert state.targets.dtype == np.float64 and state.targets.shape == (NWORLD, 7)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda s: dataclasses.replace(s, targets=s.targets[:2]), "state has 2 worlds"),
        (
            lambda s: dataclasses.replace(
                s, physics={**s.physics, "qpos": s.physics["qpos"][:, :5]}
            ),
            "'qpos' has shape",
        ),
        (
            lambda s: dataclasses.replace(
                s, physics={k: v for k, v in s.physics.items() if k != "qvel"}
            ),
            "'qvel' missing",
        ),
        (
            lambda s: dataclasses.replace(
                s, physics={**s.physics, "qvel": np.full_like(s.physics["qvel"], np.nan)}
            ),
            "non-finite",
        ),
    ],
)
def test_a_state_that_does_not_fit_changes_nothing(batch, change, message):
    drive(batch, 3, seed=5)
    before = batch.get_state()
    bad: BatchState = change(batch.get_state())
    with pytest.raises(ValueError, match=message):
        batch.set_state(bad)
    after = batch.get_state()
    assert after.tick == before.tick
    for k in PHYSICS_FIELDS:
        np.testing.assert_array_equal(after.physics[k], before.physics[k])


def test_the_snapshot_at_the_restored_tick_is_the_saved_one(batch):
    drive(batch, 7, seed=8)
    state, snap = batch.get_state(), batch.snapshot()
    fresh = WorldBatch(NWORLD)
    fresh.set_state(state)
    again = fresh.snapshot()
    assert again.tick == snap.tick
    for field in ("position", "velocity", "effort", "target", "flange_pos", "sim_time", "faults"):
        np.testing.assert_array_equal(getattr(again, field), getattr(snap, field), err_msg=field)
