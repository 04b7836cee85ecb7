"""Behavioural tests of the MJCF work cell (UR10e + Robotiq 2F-140, table, cube).

Native ``mujoco`` only.  Dynamic tests run at the engine's timestep and solver options
(service/core/sim/physics.py), so that they judge the physics the service steps.
"""

import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from mjcf import MJCF_DIR, ROBOT_XML, SCENE_XML  # noqa: E402
from service.core.sim.physics import (  # noqa: E402
    DEFAULT_PHYSICS_DT,
    ENGINE_SOLVER,
    configure,
    tick_timing,
)
from tests.rclpy import ur_joints  # noqa: E402

ENGINE_DT = tick_timing(60.0, DEFAULT_PHYSICS_DT)[1]
TWO_PI = 2.0 * np.pi

ARM_JOINTS = ur_joints.ARM
DRIVEN_JOINTS = (*ARM_JOINTS, ur_joints.GRIPPER)
JOINT_RANGES = {name: (-TWO_PI, TWO_PI) for name in ARM_JOINTS}
JOINT_RANGES["elbow_joint"] = (-np.pi, np.pi)
JOINT_RANGES["finger_joint"] = (0.0, 0.7)
EFFORTS = (330.0, 330.0, 150.0, 54.0, 54.0, 54.0)
HOME_ARM = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
# URDF mimic multipliers of the 2F-140: mimic joint = multiplier * finger_joint.
MIMIC = {
    "right_outer_knuckle_joint": -1.0,
    "left_inner_knuckle_joint": -1.0,
    "right_inner_knuckle_joint": -1.0,
    "left_inner_finger_joint": 1.0,
    "right_inner_finger_joint": 1.0,
}

# UR10e DH table: d, a, alpha (theta offsets are all zero).
DH_D = (0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655)
DH_A = (0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0)
DH_ALPHA = (np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0)


# --------------------------------------------------------------------------- helpers


@pytest.fixture(scope="module")
def model():
    m = mujoco.MjModel.from_xml_path(str(SCENE_XML))
    configure(m, ENGINE_DT, ENGINE_SOLVER["mujoco"])  # as the native engine steps it
    return m


def home_data(model):
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    return data


def set_finger(model, data, value):
    """Set finger_joint and its mimic joints consistently (positions and targets)."""
    data.qpos[model.joint("finger_joint").qposadr[0]] = value
    for name, mult in MIMIC.items():
        data.qpos[model.joint(name).qposadr[0]] = mult * value
    data.ctrl[model.actuator("finger_joint").id] = value


def dh_forward(q):
    """Standard DH: T = prod Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    t = np.eye(4)
    for theta, d, a, alpha in zip(q, DH_D, DH_A, DH_ALPHA, strict=True):
        ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
        t = t @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0.0, sa, ca, d],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return t


def rotation_angle(r):
    return float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))


def robot_geom_ids(model):
    """Geoms of the arm and gripper bodies (the subtree of `base`)."""
    base = model.body("base").id
    ids = []
    for g in range(model.ngeom):
        b = model.geom_bodyid[g]
        while b not in (0, base):
            b = model.body_parentid[b]
        if b == base:
            ids.append(g)
    return ids


def robot_contacts(model, data):
    robot = set(robot_geom_ids(model))
    return [
        (model.geom(c.geom1).name, model.geom(c.geom2).name)
        for c in data.contact[: data.ncon]
        if c.geom1 in robot or c.geom2 in robot
    ]


def assert_healthy(model, data):
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
    warnings = {
        mujoco.mjtWarning(i).name: int(data.warning[i].number)
        for i in range(mujoco.mjtWarning.mjNWARNING)
        if data.warning[i].number
    }
    assert not warnings, warnings


# --------------------------------------------------------------------------- package / contract


def test_package_points_at_the_model_files():
    assert MJCF_DIR == SCENE_XML.parent == ROBOT_XML.parent
    assert SCENE_XML.is_file() and ROBOT_XML.is_file()
    # The robot file must load on its own too.
    robot = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
    assert robot.nu == 7


def test_driven_joints_come_first_with_contract_ranges(model):
    assert model.nu == 7
    for i, name in enumerate(DRIVEN_JOINTS):
        j = model.joint(name)
        assert j.id == i, name
        assert j.qposadr[0] == i and j.dofadr[0] == i, name
        assert j.type[0] == mujoco.mjtJoint.mjJNT_HINGE
        assert j.limited[0]
        np.testing.assert_allclose(j.range, JOINT_RANGES[name], atol=1e-6)
    # Mimic joints follow finger_joint, the cube's free joint is last.
    assert {model.joint(i).name for i in range(7, 12)} == set(MIMIC)
    cube = model.joint("cube_joint")
    assert cube.type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert cube.id == model.njnt - 1 and cube.qposadr[0] == model.nq - 7


def test_seven_position_actuators_named_and_ranged_like_their_joints(model):
    for i, name in enumerate(DRIVEN_JOINTS):
        act = model.actuator(i)
        assert act.name == name
        assert act.trntype[0] == mujoco.mjtTrn.mjTRN_JOINT
        assert act.trnid[0] == model.joint(name).id
        assert act.ctrllimited[0]
        np.testing.assert_allclose(act.ctrlrange, JOINT_RANGES[name], atol=1e-6)
        # A position servo: force = kp * (ctrl - q) - kv * qdot.
        kp = act.gainprm[0]
        assert kp > 0 and act.biasprm[1] == pytest.approx(-kp) and act.biasprm[2] < 0
    for i, effort in enumerate(EFFORTS):
        np.testing.assert_allclose(model.actuator(i).forcerange, (-effort, effort))
        np.testing.assert_allclose(model.jnt_actfrcrange[i], (-effort, effort))
        assert model.jnt_actgravcomp[i]


def test_velocity_limits_are_published_for_the_seven_joints(model):
    vel = model.numeric("velocity_limit").data
    np.testing.assert_allclose(vel, (2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416, 2.0))


def test_home_keyframe_is_consistent(model):
    key = model.key("home")
    np.testing.assert_allclose(key.qpos[:7], (*HOME_ARM, 0.0))
    np.testing.assert_allclose(key.ctrl, (*HOME_ARM, 0.0))
    for name in MIMIC:
        assert key.qpos[model.joint(name).qposadr[0]] == 0.0
    # The cube rests on the table: settle 0.5 s, it must not move.
    data = home_data(model)
    start = data.body("cube").xpos.copy()
    mujoco.mj_step(model, data, nstep=int(0.5 / ENGINE_DT))
    np.testing.assert_allclose(data.body("cube").xpos, start, atol=5e-4)
    table_top = data.geom("table_top").xpos[2] + model.geom("table_top").size[2]
    assert data.body("cube").xpos[2] == pytest.approx(table_top + 0.025, abs=1e-3)
    np.testing.assert_allclose(data.qpos[:6], HOME_ARM, atol=2e-3)


def test_collision_geoms_are_cheap_primitives_without_arm_self_collision(model):
    cheap = {
        int(t)
        for t in (
            mujoco.mjtGeom.mjGEOM_PLANE,
            mujoco.mjtGeom.mjGEOM_SPHERE,
            mujoco.mjtGeom.mjGEOM_CAPSULE,
            mujoco.mjtGeom.mjGEOM_BOX,
        )
    }
    robot = robot_geom_ids(model)
    for g in range(model.ngeom):
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            assert int(model.geom_type[g]) in cheap, model.geom(g).name
    for g1 in robot:
        for g2 in robot:
            filtered = not (
                model.geom_contype[g1] & model.geom_conaffinity[g2]
                or model.geom_contype[g2] & model.geom_conaffinity[g1]
            )
            assert filtered, (model.geom(g1).name, model.geom(g2).name)
    # The pads do collide with the cube.
    pad, cube = model.geom("left_pad").id, model.geom("cube_geom").id
    assert model.geom_contype[cube] & model.geom_conaffinity[pad]


# --------------------------------------------------------------------------- kinematics


def test_flange_site_matches_dh_forward_kinematics(model):
    rng = np.random.default_rng(1234)
    data = mujoco.MjData(model)
    base, flange = model.site("dh_base").id, model.site("flange").id
    worst_pos = worst_rot = 0.0
    for _ in range(200):
        q = rng.uniform(-np.pi, np.pi, 6)
        data.qpos[:6] = q
        mujoco.mj_kinematics(model, data)
        rb = data.site_xmat[base].reshape(3, 3)
        rel_pos = rb.T @ (data.site_xpos[flange] - data.site_xpos[base])
        rel_rot = rb.T @ data.site_xmat[flange].reshape(3, 3)
        t = dh_forward(q)
        worst_pos = max(worst_pos, float(np.linalg.norm(rel_pos - t[:3, 3])))
        worst_rot = max(worst_rot, rotation_angle(t[:3, :3].T @ rel_rot))
    assert worst_pos <= 1e-3, worst_pos
    assert worst_rot <= 1e-3, worst_rot


# --------------------------------------------------------------------------- dynamics


def random_free_pose(model, rng):
    """A random arm pose well clear of table, floor and pedestal (no robot contact)."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    low_bodies = [model.body(n).id for n in ("wrist_2_link", "wrist_3_link", "gripper_base")]
    for _ in range(1000):
        q = np.array(HOME_ARM) + rng.uniform(-1.0, 1.0, 6)
        data.qpos[:6] = q
        mujoco.mj_forward(model, data)
        clear = all(data.xpos[b][2] > 1.0 for b in low_bodies)
        if clear and data.site("pinch").xpos[2] > 0.9 and not robot_contacts(model, data):
            return q
    raise AssertionError("no free pose found")


def test_arm_holds_random_poses_under_gravity(model):
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(5):
        pose = random_free_pose(model, rng)
        data = home_data(model)
        data.qpos[:6] = pose
        data.ctrl[:6] = pose
        set_finger(model, data, rng.uniform(0.0, 0.7))
        n = round(2.0 / ENGINE_DT)
        for k in range(n):
            mujoco.mj_step(model, data)
            if k >= n // 2:
                worst = max(worst, float(np.abs(data.qpos[:6] - pose).max()))
        assert not robot_contacts(model, data)
    assert worst <= 0.002, worst


@pytest.mark.parametrize("joint", DRIVEN_JOINTS)
def test_joint_step_response_settles_fast_without_overshoot(model, joint):
    data = home_data(model)
    i = model.joint(joint).qposadr[0]
    if joint == "finger_joint":
        set_finger(model, data, 0.3)
        mujoco.mj_step(model, data, nstep=int(0.5 / ENGINE_DT))
    start = data.qpos[i].copy()
    step = 0.1
    data.ctrl[model.actuator(joint).id] = start + step
    n = round(1.5 / ENGINE_DT)
    t = np.arange(1, n + 1) * ENGINE_DT
    progress = np.empty(n)
    for k in range(n):
        mujoco.mj_step(model, data)
        progress[k] = (data.qpos[i] - start) / step
    outside = np.nonzero(np.abs(progress - 1.0) > 0.02)[0]
    settle = t[outside[-1]] if outside.size else 0.0
    overshoot = max(0.0, progress.max() - 1.0)
    assert settle <= 0.5, f"{joint}: settles at {settle:.3f} s"
    assert overshoot <= 0.05, f"{joint}: overshoot {overshoot:.1%}"


def test_mimic_joints_follow_finger_joint(model):
    data = home_data(model)
    fj = model.joint("finger_joint").qposadr[0]
    for target in (0.0, 0.2, 0.45, 0.7, 0.1):
        data.ctrl[model.actuator("finger_joint").id] = target
        mujoco.mj_step(model, data, nstep=int(0.6 / ENGINE_DT))
        assert data.qpos[fj] == pytest.approx(target, abs=5e-3)
        for name, mult in MIMIC.items():
            q = data.qpos[model.joint(name).qposadr[0]]
            assert q == pytest.approx(mult * data.qpos[fj], abs=2e-3), (name, target)


# --------------------------------------------------------------------------- grasp


def solve_ik(model, data, q_start, pinch_goal, flange_rot_goal):
    """Damped least squares on the six arm joints: pinch site position + flange orientation."""
    scratch = mujoco.MjData(model)
    scratch.qpos[:] = data.qpos
    pinch, flange = model.site("pinch").id, model.site("flange").id
    jp = np.zeros((3, model.nv))
    jr = np.zeros((3, model.nv))
    quat = np.zeros(4)
    q = np.array(q_start, dtype=float)
    err = np.inf
    for _ in range(100):
        scratch.qpos[:6] = q
        mujoco.mj_kinematics(model, scratch)
        mujoco.mj_comPos(model, scratch)
        e_pos = pinch_goal - scratch.site_xpos[pinch]
        r_err = flange_rot_goal @ scratch.site_xmat[flange].reshape(3, 3).T
        mujoco.mju_mat2Quat(quat, r_err.ravel())
        e_rot = np.zeros(3)
        mujoco.mju_quat2Vel(e_rot, quat, 1.0)
        e = np.concatenate([e_pos, e_rot])
        err = float(np.linalg.norm(e))
        if err < 1e-9:
            break
        mujoco.mj_jacSite(model, scratch, jp, None, pinch)
        mujoco.mj_jacSite(model, scratch, None, jr, flange)
        jac = np.vstack([jp, jr])[:, :6]
        q += jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), e)
    assert err < 1e-6, err
    return q


def test_gripper_grasps_lifts_and_holds_the_cube(model):
    data = home_data(model)
    mujoco.mj_step(model, data, nstep=int(0.2 / ENGINE_DT))
    cube = model.body("cube").id
    cube_start = data.xpos[cube].copy()
    flange_rot = data.site("flange").xmat.reshape(3, 3).copy()
    assert flange_rot[2, 2] < -0.99  # tool axis points down at home

    home = data.qpos[:6].copy()
    # The pads' centres at contact sit 2 cm above the cube centre: their lower edges stay 1 cm
    # clear of the table.
    q_grasp = solve_ik(model, data, home, cube_start + np.array([0.0, 0.0, 0.02]), flange_rot)
    q_lift = solve_ik(model, data, q_grasp, cube_start + np.array([0.0, 0.0, 0.12]), flange_rot)

    def move(q_from, q_to, seconds, finger=None):
        n = round(seconds / ENGINE_DT)
        for k in range(n):
            s = min(1.0, 1.5 * (k + 1) / n)
            data.ctrl[:6] = q_from + s * (q_to - q_from)
            if finger is not None:
                data.ctrl[6] = finger * s
            mujoco.mj_step(model, data)

    move(home, q_grasp, 1.2)
    move(q_grasp, q_grasp, 0.8, finger=0.7)
    assert data.qpos[6] < 0.6  # the cube stops the fingers
    move(q_grasp, q_lift, 1.2)

    hold = []
    for _ in range(round(2.0 / ENGINE_DT)):
        mujoco.mj_step(model, data)
        hold.append(data.xpos[cube].copy())
    hold = np.array(hold)
    rise = hold[:, 2] - cube_start[2]
    assert rise.min() >= 0.095, rise.min()
    assert rise.max() - rise.min() <= 0.01
    # Cube between the pads: its centre projects inside the pad-to-pad segment and lies close
    # to that segment.
    left, right = data.geom("left_pad").xpos, data.geom("right_pad").xpos
    axis = right - left
    s = float(np.dot(data.xpos[cube] - left, axis) / np.dot(axis, axis))
    assert 0.2 < s < 0.8, s
    off_axis = np.linalg.norm(data.xpos[cube] - (left + s * axis))
    assert off_axis < 0.03, off_axis
    touching = {
        frozenset((model.geom(c.geom1).name, model.geom(c.geom2).name))
        for c in data.contact[: data.ncon]
    }
    assert frozenset(("left_pad", "cube_geom")) in touching
    assert frozenset(("right_pad", "cube_geom")) in touching
    assert_healthy(model, data)


# --------------------------------------------------------------------------- stability


def test_random_target_presses_for_60_s_stay_finite_without_warnings(model):
    rng = np.random.default_rng(42)
    data = home_data(model)
    low, high = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    steps_per_press = round(0.1 / ENGINE_DT)
    for _ in range(600):
        j = rng.integers(7)
        data.ctrl[j] = np.clip(data.ctrl[j] + rng.choice((-0.1, 0.1)), low[j], high[j])
        mujoco.mj_step(model, data, nstep=steps_per_press)
        assert np.abs(data.qvel).max() < 50.0
    assert_healthy(model, data)
    # Still a well-behaved servo afterwards: sent home, it gets there and stays.
    data.ctrl[:] = model.key("home").ctrl
    mujoco.mj_step(model, data, nstep=round(3.0 / ENGINE_DT))
    np.testing.assert_allclose(data.qpos[:7], model.key("home").ctrl, atol=2e-3)
    assert np.abs(data.qvel[:7]).max() < 1e-3
    assert_healthy(model, data)
