"""The flange pose frames and snapshots carry (service.engines.chain_pose) against MuJoCo's."""

from __future__ import annotations

import pickle

import mujoco
import numpy as np
import pytest

from service.core.sim.robot import load_robot
from service.core.sim.types import Poses
from service.engines.chain_pose import ChainPose


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def _mujoco_site(mjm: mujoco.MjModel, site: int, qpos: np.ndarray) -> tuple[np.ndarray, ...]:
    data = mujoco.MjData(mjm)
    pos, quat = [], []
    for row in qpos:
        data.qpos[:] = row
        mujoco.mj_kinematics(mjm, data)
        pos.append(data.site_xpos[site].copy())
        q = np.empty(4)
        mujoco.mju_mat2Quat(q, data.site_xmat[site])
        quat.append(q * np.sign(q[0]))
    return np.array(pos), np.array(quat)


def test_flange_pose_equals_mujoco_kinematics_anywhere(robot):
    mjm, site = robot.mjm, robot.flange_site
    rng = np.random.default_rng(7)
    qpos = np.tile(mjm.qpos0, (200, 1))
    for adr in robot.qpos_adr[:6]:
        qpos[:, adr] = rng.uniform(-2 * np.pi, 2 * np.pi, 200)
    pos, quat = ChainPose(mjm, site).pose(qpos)
    ref_pos, ref_quat = _mujoco_site(mjm, site, qpos)
    np.testing.assert_allclose(pos, ref_pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(quat * np.sign(quat[:, :1]), ref_quat, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, rtol=0, atol=1e-15)


def test_a_subset_of_worlds_gets_the_same_bits_as_all_of_them(robot):
    rng = np.random.default_rng(8)
    qpos = np.tile(robot.mjm.qpos0, (513, 1))
    qpos[:, robot.qpos_adr[:6]] = rng.uniform(-3, 3, (513, 6))
    chain = ChainPose(robot.mjm, robot.flange_site)
    pos, quat = chain.pose(qpos)
    for ids in (np.array([5]), np.arange(0, 513, 3), np.array([0, 511, 512])):
        sub_pos, sub_quat = chain.pose(qpos[ids])
        assert np.array_equal(sub_pos, pos[ids]) and np.array_equal(sub_quat, quat[ids])


def test_a_site_behind_a_free_joint_is_refused():
    spec = mujoco.MjSpec.from_string(
        '<mujoco><worldbody><body><freejoint/><geom size=".1"/><site name="s"/></body>'
        "</worldbody></mujoco>"
    )
    mjm = spec.compile()
    with pytest.raises(ValueError, match="neither a hinge nor a slide"):
        ChainPose(mjm, 0)


def test_body_poses_are_computed_once_on_first_read_and_pickle_as_arrays():
    calls = []

    def compute():
        calls.append(1)
        return np.ones((2, 3, 3), np.float32), np.zeros((2, 3, 4), np.float32)

    poses = Poses(compute=compute)
    assert calls == []
    first, again = poses.get(), poses.get()
    assert calls == [1] and first[0] is again[0]
    copy = pickle.loads(pickle.dumps(Poses(compute=compute)))
    assert np.array_equal(copy.get()[0], first[0]) and len(calls) == 2
    with pytest.raises(ValueError):
        Poses()


def test_the_native_engine_falls_back_to_mujoco_kinematics_off_a_chain():
    """A model whose flange is not on a hinge/slide chain gets MuJoCo's pose (same numbers)."""
    from service.engines.native import NativeBatch

    batch = NativeBatch(3)
    rng = np.random.default_rng(9)
    qpos = batch.qpos()
    qpos[:, batch.robot.qpos_adr[:6]] = rng.uniform(-3, 3, (3, 6))
    poses = batch._poses
    chain_pos, chain_quat = poses.flange(qpos)
    poses._chain = None  # as for a model ChainPose refuses
    mj_pos, mj_quat = poses.flange(qpos)
    np.testing.assert_allclose(mj_pos, chain_pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(mj_quat, chain_quat, rtol=0, atol=1e-12)  # the same sign too
    sub_pos, _ = poses.flange(qpos[[2]])  # fewer rows than worlds
    np.testing.assert_allclose(sub_pos[0], mj_pos[2], rtol=0, atol=0)
