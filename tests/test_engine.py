"""Both engines (WorldBatch on MuJoCo Warp, NativeBatch on native MuJoCo): tick-zero state,
grasp, 60 s of presses, fidelity against plain mj_step and against each other; warp's capture.

Targets, masked resets and fault isolation are checked for every engine in test_batch_contract.py.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from test_model import solve_ik

from service.engines.native import NativeBatch
from service.engines.warp import WorldBatch

NWORLD = 4
ENGINES = {"warp": WorldBatch, "mujoco": NativeBatch}


@pytest.fixture(scope="module", params=sorted(ENGINES))
def engine(request: pytest.FixtureRequest) -> type[WorldBatch] | type[NativeBatch]:
    return ENGINES[request.param]


@pytest.fixture(scope="module")
def twins(engine) -> tuple[WorldBatch, WorldBatch]:
    """Two identical batches: one is disturbed, the other is the undisturbed reference."""
    return engine(NWORLD), engine(NWORLD)


@pytest.fixture
def fresh(twins):
    for b in twins:
        b.reset(np.arange(NWORLD))
    return twins


def test_tick_is_captured_and_replays_like_uncaptured_stepping():
    captured = WorldBatch(2)
    plain = WorldBatch(2, capture=False)
    assert captured.captured and not plain.captured
    for b in (captured, plain):
        b.apply_targets(np.array([1]), np.array([[0.3, -1.2, 1.2, -1.5, -1.5, 0.4, 0.5]]))
        b.step(5)
    np.testing.assert_array_equal(captured.qpos(), plain.qpos())
    assert captured.tick == plain.tick == 5


def test_tick_zero_snapshot_is_home_with_exact_sim_time(fresh):
    batch, _ = fresh
    snap = batch.snapshot()
    np.testing.assert_allclose(snap.position, np.tile(batch.home_target, (NWORLD, 1)), atol=1e-6)
    batch.step(3)
    snap = batch.snapshot()
    assert snap.tick == batch.tick
    np.testing.assert_allclose(snap.sim_time, 3 / 60.0)
    assert batch.substeps * batch.physics_dt == pytest.approx(1 / 60.0)
    assert snap.flange_quat.shape == (NWORLD, 4)
    np.testing.assert_allclose(np.linalg.norm(snap.flange_quat, axis=1), 1.0, atol=1e-5)


def test_grasp_never_overflows_capacity(fresh):
    """World 1 grasps and lifts the cube through the engine; no contact or row is dropped."""
    batch, _ = fresh
    mjm = batch.robot.mjm
    data = mujoco.MjData(mjm)
    mujoco.mj_resetDataKeyframe(mjm, data, batch.robot.home_key)
    mujoco.mj_forward(mjm, data)
    cube_z = mjm.jnt_qposadr[mjm.joint("cube_joint").id] + 2
    cube = data.xpos[mjm.body("cube").id].copy()
    flange_rot = data.site("flange").xmat.reshape(3, 3).copy()
    home = batch.home_target[:6]
    q_grasp = solve_ik(mjm, data, home, cube + [0, 0, 0.02], flange_rot)
    q_lift = solve_ik(mjm, data, q_grasp, cube + [0, 0, 0.12], flange_rot)
    z0 = batch.qpos()[1, cube_z]
    faults_before = batch.snapshot().faults.copy()

    peak_rows = 0

    def move(q_from, q_to, seconds, finger_from, finger_to):
        nonlocal peak_rows
        n = round(seconds * batch.control_hz)
        for k in range(n):
            s = min(1.0, 1.5 * (k + 1) / n)
            arm = q_from + s * (q_to - q_from)
            finger = finger_from + s * (finger_to - finger_from)
            batch.apply_targets(np.array([1]), np.append(arm, finger)[None])
            batch.step(1)
            peak_rows = max(peak_rows, batch.capacity_usage()[1])

    move(home, q_grasp, 1.2, 0.0, 0.0)
    move(q_grasp, q_grasp, 0.8, 0.0, 0.7)
    move(q_grasp, q_lift, 1.2, 0.7, 0.7)
    batch.step(120)  # hold 2 s
    rise = batch.qpos()[1, cube_z] - z0
    assert rise > 0.09, rise
    np.testing.assert_array_equal(batch.snapshot().faults, faults_before)
    assert 40 < peak_rows < 128  # the pads really touched, and well inside capacity


def test_warp_newton_ends_most_resting_steps_at_the_warm_start(fresh):
    """service/engines/warp_newton.py: at rest a world whose warm start passes CG's test takes
    no iteration (no Hessian); a pressed world is still solved (fidelity: the tests below)."""
    batch, _ = fresh
    if not isinstance(batch, WorldBatch):
        pytest.skip("MuJoCo Warp's Newton solve")
    batch.step(30)
    niter = []
    for _ in range(30):
        batch.step(1)
        niter.append(batch._d.solver_niter.numpy().copy())  # the tick's last substep
    assert (np.array(niter) == 0).mean() > 0.2, np.array(niter)
    target = batch.home_target.copy()
    target[1] += 0.1
    batch.apply_targets(np.array([1]), target[None])
    batch.step(1)
    assert batch._d.solver_niter.numpy()[1] >= 1


def test_float32_warp_tracks_float64_native_mujoco_within_a_milliradian():
    """The warp engine against plain mj_step on one MjData, the same commands."""
    batch = WorldBatch(1)
    mjm = batch.robot.mjm  # timestep already set to the engine's substep
    data = mujoco.MjData(mjm)
    mujoco.mj_resetDataKeyframe(mjm, data, batch.robot.home_key)
    rng = np.random.default_rng(7)
    target = batch.home_target.copy()
    worst = 0.0
    for tick in range(120):  # 2 s of presses, one every 0.1 s
        if tick % 6 == 0:
            j = rng.integers(6)
            target[j] += rng.choice([-0.1, 0.1])
        batch.apply_targets(np.array([0]), target[None])
        data.ctrl[:] = target
        mujoco.mj_step(mjm, data, nstep=batch.substeps)
        batch.step(1)
        warp_q = batch.snapshot().position[0]
        native_q = data.qpos[batch.robot.qpos_adr]
        worst = max(worst, float(np.abs(warp_q - native_q).max()))
    assert worst < 1e-3, worst


def test_warp_and_native_engines_agree_within_a_milliradian_over_2_s():
    """The two engines through the same Batch calls, every world a different command sequence."""
    warp, native = WorldBatch(NWORLD), NativeBatch(NWORLD)
    rng = np.random.default_rng(11)
    targets = np.tile(warp.home_target, (NWORLD, 1))
    worst = 0.0
    for tick in range(120):
        if tick % 6 == 0:
            targets[np.arange(NWORLD), rng.integers(7, size=NWORLD)] += rng.choice(
                [-0.1, 0.1], size=NWORLD
            )
            for b in (warp, native):
                b.apply_targets(np.arange(NWORLD), targets)
        for b in (warp, native):
            assert b.step(1).size == 0
        a, n = warp.snapshot(), native.snapshot()
        worst = max(worst, float(np.abs(a.position - n.position).max()))
    assert worst < 1e-3, worst
    np.testing.assert_allclose(a.flange_pos, n.flange_pos, atol=2e-3)
    np.testing.assert_allclose(a.target, n.target)


def test_native_engine_is_bit_identical_to_mj_step_per_world():
    """NativeBatch on its thread pool = one MjData per world stepped by mj_step, exactly."""
    batch = NativeBatch(3, nthread=2)
    mjm = batch.robot.mjm
    datas = [mujoco.MjData(mjm) for _ in range(3)]
    for d in datas:
        mujoco.mj_resetDataKeyframe(mjm, d, batch.robot.home_key)
    targets = np.tile(batch.home_target, (3, 1))
    targets[:, 0] += 0.2 * np.arange(3)
    targets[:, 2] -= 0.1 * np.arange(3)
    targets[:, 6] = 0.35
    batch.apply_targets(np.arange(3), targets)
    for d, t in zip(datas, batch.targets, strict=True):
        d.ctrl[:] = t
    for _ in range(30):
        batch.step(1)
        for d in datas:
            mujoco.mj_step(mjm, d, nstep=batch.substeps)
    snap = batch.snapshot()  # float32 states, as the warp engine reports them
    for w, d in enumerate(datas):
        np.testing.assert_array_equal(batch.qpos()[w], d.qpos)
        np.testing.assert_array_equal(
            snap.effort[w], d.qfrc_actuator[batch.robot.dof_adr].astype(np.float32)
        )
        mujoco.mj_kinematics(mjm, d)  # the flange is reported at the state, not a substep before
        np.testing.assert_array_equal(
            snap.flange_pos[w], d.site_xpos[batch.robot.flange_site].astype(np.float32)
        )
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, d.site_xmat[batch.robot.flange_site])
        assert abs(abs(float(quat @ snap.flange_quat[w])) - 1.0) < 1e-6


def test_native_engine_resets_a_diverging_world_alone():
    """|qvel| over the limit (still finite) is a fault too; MuJoCo's own reset is not enough."""
    batch, reference = NativeBatch(NWORLD), NativeBatch(NWORLD)
    for b in (batch, reference):
        b.step(5)
    batch._qvel[2, 0] = 2.0e4  # no API spins a joint like this
    assert batch.step(1).tolist() == [2]
    reference.step(1)
    assert batch.snapshot().faults.tolist() == [0, 0, 1, 0]
    np.testing.assert_array_equal(batch.qpos()[[0, 1, 3]], reference.qpos()[[0, 1, 3]])


def test_random_presses_for_60_s_never_produce_nan_in_any_world(engine):
    batch = engine(NWORLD)
    rng = np.random.default_rng(3)
    targets = np.tile(batch.home_target, (NWORLD, 1))
    lo, hi = batch.spec.lower, batch.spec.upper
    for tick in range(60 * 60):
        if tick % 6 == 0:  # every world gets a press every 0.1 s
            joints = rng.integers(7, size=NWORLD)
            targets[np.arange(NWORLD), joints] += rng.choice([-0.1, 0.1], size=NWORLD)
            targets = np.clip(targets, lo, hi)
            batch.apply_targets(np.arange(NWORLD), targets)
        assert batch.step(1).size == 0, f"a world faulted at tick {tick}"
    assert np.isfinite(batch.qpos()).all()
    assert batch.snapshot().faults.sum() == 0
