"""The arm's kinematics (service.core.kinematics) against MuJoCo's own: forward kinematics of
the flange equals `mj_kinematics`' site pose on the served model at random joint angles, the
closed-form IK round-trips, and what it cannot reach it says so, for many worlds in one call."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from mjcf import SCENE_XML
from service.core.errors import BadCommand
from service.core.kinematics.clearance import Clearance
from service.core.kinematics.line import MAX_SAMPLES, plan_line, sample_times
from service.core.kinematics.pose import (
    matrix_to_pose,
    matrix_to_quat,
    pose_to_matrix,
    quat_to_matrix,
    rotvec_to_matrix,
)
from service.core.kinematics.servo import ServoLag
from service.core.kinematics.ur import NotDH, Singularity, Unsolved, URKinematics
from service.core.sim.robot import FLANGE_SITE, load_robot
from service.core.sim.types import Snapshot
from service.surfaces.ur.rtde_frame import Frame, FrameValues
from service.surfaces.ur.tcp_pose import ToolKinematics

ROBOT = load_robot()
ARM = ROBOT.spec.names[:6]
KIN = URKinematics.from_model(ROBOT.mjm, ARM)
LIMITS = np.array([j.velocity_limit for j in ROBOT.spec.joints[:6]])
RNG = np.random.default_rng(40)


def _mujoco_flange(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's flange site poses (world frame) at arm angles q (n, 6): positions, matrices."""
    data = mujoco.MjData(ROBOT.mjm)
    site = mujoco.mj_name2id(ROBOT.mjm, mujoco.mjtObj.mjOBJ_SITE, FLANGE_SITE)
    pos, mat = [], []
    for row in q:
        data.qpos[ROBOT.qpos_adr[:6]] = row
        mujoco.mj_kinematics(ROBOT.mjm, data)
        pos.append(data.site_xpos[site].copy())
        mat.append(data.site_xmat[site].reshape(3, 3).copy())
    return np.array(pos), np.array(mat)


def test_forward_kinematics_equals_mujoco_within_a_micrometre_at_random_angles() -> None:
    q = RNG.uniform(KIN.lower, KIN.upper, (500, 6))
    pos, mat = _mujoco_flange(q)
    world = KIN.to_world(KIN.flange(q))
    assert np.abs(world[:, :3, 3] - pos).max() < 1e-6
    assert np.abs(world[:, :3, :3] - mat).max() < 1e-6
    # the base frame is MuJoCo's `base` body: at (0, 0, 0.5) turned π about z in the scene
    assert KIN.base_in_world[:3, 3] == pytest.approx([0, 0, 0.5])
    assert np.diag(KIN.base_in_world[:3, :3]) == pytest.approx([-1, -1, 1])
    # the DH lengths read off the model are UR's published UR10e table
    assert KIN.d[[0, 3, 4, 5]] == pytest.approx([0.1807, 0.17415, 0.11985, 0.11655], abs=1e-12)
    assert KIN.a[[1, 2]] == pytest.approx([-0.6127, -0.57155], abs=1e-12)


def test_the_tcp_offset_is_composed_in_the_flange_frame_as_set_tcp() -> None:
    q = RNG.uniform(-np.pi, np.pi, (50, 6))
    tcp = np.array([0.01, -0.02, 0.2, 0.1, -0.2, 0.3])
    pos, mat = _mujoco_flange(q)
    got = KIN.to_world(KIN.tcp(q, np.tile(tcp, (50, 1))))
    want = pos + np.einsum("nij,j->ni", mat, tcp[:3])
    assert np.abs(got[:, :3, 3] - want).max() < 1e-6
    assert np.abs(got[:, :3, :3] - mat @ rotvec_to_matrix(tcp[3:])).max() < 1e-6


def test_ik_round_trips_within_1e_6_for_many_worlds_at_once() -> None:
    q = RNG.uniform(KIN.lower, KIN.upper, (2000, 6))
    tcp = np.tile([0.0, 0.0, 0.15, 0.0, 0.0, 0.5], (2000, 1))
    pose = KIN.fk(q, tcp)
    got = KIN.ik(pose, q + RNG.normal(0, 0.05, q.shape), tcp)
    assert got.ok.all()
    assert np.abs(KIN.fk(got.q, tcp)[:, :3] - pose[:, :3]).max() < 1e-6
    back = KIN.tcp(got.q, tcp)[:, :3, :3] - pose_to_matrix(pose)[:, :3, :3]
    assert np.abs(back).max() < 1e-6
    # nearest q_near: the configuration it came from, each joint on its own turn
    assert np.abs(KIN.ik(pose, q, tcp).q - q).max() < 1e-6
    sols, valid = KIN.ik_all(pose[:10], tcp[:10])
    assert sols.shape == (10, 8, 6) and valid.any(axis=1).all()


def test_unreachable_poses_and_singularities_are_reported_not_raised() -> None:
    home = ROBOT.spec.home[None, :6]
    far = np.array([[2.0, 0, 0.5, 0, 0, 0], [0, 0, 0.18, 0, 0, 0]])  # beyond reach; in the base
    got = KIN.ik(far, np.repeat(home, 2, 0))
    assert not got.ok.any() and (got.reason == Unsolved.OUT_OF_REACH).all()
    assert got.why(0) == "out_of_reach" and np.array_equal(got.q, np.repeat(home, 2, 0))
    # a pose only an elbow past ±π reaches: solutions exist, none inside the elbow's range
    lower, upper = KIN.lower.copy(), KIN.upper.copy()
    lower[2], upper[2] = -0.1, 0.1
    narrow = URKinematics(KIN.d, KIN.a, lower, upper, KIN.flange_in_dh6, KIN.base_in_world)
    q = np.array([[0.3, -1.0, 1.5, -1.0, 1.2, 0.2]])
    assert narrow.ik(narrow.fk(q), q).why(0) == "joint_limits"
    straight = np.array([[0.0, -1.0, 0.0, -1.0, 0.0, 0.0]])  # elbow straight, wrist aligned
    bits = int(KIN.singularity(straight)[0])
    assert Singularity.names(bits) == ["wrist", "elbow"]
    got = KIN.ik(KIN.fk(straight), straight)
    assert got.ok[0] and np.abs(KIN.fk(got.q) - KIN.fk(straight))[:, :3].max() < 1e-6


def test_the_jacobian_is_the_derivative_of_the_tcp_pose() -> None:
    q, tcp = RNG.uniform(-3, 3, (20, 6)), np.tile([0.0, 0.05, 0.2, 0.3, 0, 0], (20, 1))
    jac, eps = KIN.jacobian(q, tcp), 1e-6
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = eps
        hi, lo = KIN.tcp(q + dq, tcp), KIN.tcp(q - dq, tcp)
        v = (hi[:, :3, 3] - lo[:, :3, 3]) / (2 * eps)
        w = (
            (hi[:, :3, :3] - lo[:, :3, :3])
            / (2 * eps)
            @ KIN.tcp(q, tcp)[:, :3, :3].transpose(0, 2, 1)
        )
        assert np.abs(jac[:, :3, j] - v).max() < 1e-7
        assert np.abs(jac[:, 3:, j] - w[:, [2, 0, 1], [1, 2, 0]]).max() < 1e-7


def test_tcp_state_of_many_worlds_is_fk_and_the_jacobian_and_mujocos_own() -> None:
    """RTDE's batched TCP pose and speed (once a tick for every world) equal `fk` and J·q̇,
    and MuJoCo's own site pose and Jacobian world by world (what RTDE read before)."""
    n = 12
    q, qd = RNG.uniform(-3, 3, (n, 6)), RNG.uniform(-2, 2, (n, 6))
    tcp = np.c_[RNG.uniform(-0.2, 0.2, (n, 3)), RNG.uniform(-1, 1, (n, 3))]
    tcp[0] = 0.0  # the flange itself
    pose, speed = KIN.tcp_state(q, qd, tcp)
    assert np.abs(pose - KIN.fk(q, tcp)).max() < 1e-12
    assert np.abs(speed - np.einsum("nij,nj->ni", KIN.jacobian(q, tcp), qd)).max() < 1e-12
    mj = ToolKinematics(ROBOT)
    for w in range(n):
        want_pose, want_speed = mj.tcp(q[w], qd[w], tuple(tcp[w]))
        assert np.abs(pose[w] - want_pose).max() < 1e-9
        assert np.abs(speed[w] - want_speed).max() < 1e-9


def test_rtde_frame_values_of_a_dh_arm_and_of_the_fallback_agree() -> None:
    """RTDE's per-tick values (rtde_frame): the batch over the DH chain and MuJoCo's own
    kinematics world by world (an arm that is not UR's chain) give the same TCP, and each
    world's row is its own."""
    n = 5
    a = lambda: RNG.uniform(-2, 2, (n, 7))  # noqa: E731
    snap = Snapshot(7, np.zeros(n), a(), a(), a(), a(), np.zeros(n), None, None)  # type: ignore[arg-type]
    frame = Frame(snap, a(), a(), 0.002)
    mj = ToolKinematics(ROBOT)
    batch = FrameValues(frame, KIN, (0, pose_to_matrix(np.zeros((n, 6)))), mj)
    alone = FrameValues(frame, None, (-1, None), mj)
    for which in ("actual_tcp", "target_tcp"):
        for got, want in zip(getattr(batch, which), getattr(alone, which), strict=True):
            assert np.abs(np.array(got) - np.array(want)).max() < 1e-9
    assert batch.q[3] == snap.position[3, :6].tolist()
    assert batch.target_qd[4] == frame.target_qd[4, :6].tolist()
    assert batch.timestamp == (7 * 0.002,)


def test_pose_conversions_keep_the_axis_near_half_a_turn() -> None:
    r = np.array([[np.pi, 0, 0], [0, np.pi - 1e-12, 0], [1e-12, 0, 0], [0.3, -2.0, 1.0]])
    t = np.zeros((4, 4, 4))
    t[:, :3, :3], t[:, 3, 3] = rotvec_to_matrix(r), 1
    back = matrix_to_pose(t)[:, 3:]
    assert np.abs(rotvec_to_matrix(back) - t[:, :3, :3]).max() < 1e-12
    assert back[1] == pytest.approx([0, np.pi - 1e-12, 0]) and back[3] == pytest.approx(r[3])
    assert np.abs(quat_to_matrix(matrix_to_quat(t[:, :3, :3])) - t[:, :3, :3]).max() < 1e-12


def test_a_line_plan_stays_on_the_line_and_refuses_what_no_arm_can_follow() -> None:
    home, tcp = ROBOT.spec.home[:6], np.array([0, 0, 0.2, 0, 0, 0.0])
    start = KIN.fk(home[None], tcp[None])[0]
    goal = start + [0.2, -0.3, -0.1, 0, 0, 0]
    plan = plan_line(KIN, home, goal, tcp, 0.25, 1.2, LIMITS, tuple(ARM))
    p = KIN.fk(plan.q, np.tile(tcp, (len(plan.q), 1)))[:, :3] - start[:3]
    u = (goal - start)[:3] / np.linalg.norm((goal - start)[:3])
    assert np.linalg.norm(p - np.outer(p @ u, u), axis=1).max() < 1e-9
    assert plan.qd[-1] == pytest.approx(np.zeros(6)) and plan.q[-1] == pytest.approx(
        KIN.ik(goal[None], home[None], tcp[None]).q[0]
    )
    led = plan_line(KIN, home, goal, tcp, 0.25, 1.2, LIMITS, tuple(ARM), ServoLag(ROBOT.mjm, ARM))
    assert 1e-5 < np.abs(led.q - plan.q).max() < 0.05  # ahead by the servos' lag, not more
    with pytest.raises(BadCommand) as fast:
        plan_line(KIN, home, goal, tcp, 3.0, 100, LIMITS, tuple(ARM))
    assert fast.value.field == "speed" and "rad/s" in fast.value.message
    with pytest.raises(BadCommand) as far:
        plan_line(KIN, home, start + [3, 0, 0, 0, 0, 0], tcp, 0.2, 1, LIMITS, tuple(ARM))
    assert far.value.field == "pose"


def test_line_samples_fall_on_the_loops_ticks_every_tick_of_the_ramps() -> None:
    """A sample on every tick is read by the trajectory runner as it is (no Hermite average
    of the led positions between samples: kinematics/line.py says why it matters)."""
    home, tcp = ROBOT.spec.home[:6], np.array([0, 0, 0.2, 0, 0, 0.0])
    goal = KIN.fk(home[None], tcp[None])[0] + [0.15, -0.25, -0.1, 0, 0, 0]
    plan = plan_line(KIN, home, goal, tcp, 0.25, 1.2, LIMITS, tuple(ARM), tick_dt=1 / 60)
    assert np.array_equal(plan.times, np.arange(1, len(plan.times) + 1) * (1 / 60))
    for total, ramp, tick in ((1.56, 0.33, 0.002), (10.0, 0.33, 0.002), (100.0, 3.0, 0.002)):
        t = sample_times(total, ramp, tick)
        ticks = np.round(t / tick)
        assert np.abs(t - ticks * tick).max() < 1e-9 and len(t) <= MAX_SAMPLES
        assert total <= t[-1] < total + tick and (np.diff(ticks) > 0).all()
        if len(t) < total / tick and ramp / tick < MAX_SAMPLES / 2:  # spaced: not the ramps
            each = round(ramp / tick)
            assert (np.diff(ticks[:each]) == 1).all() and (np.diff(ticks[-each:]) == 1).all()


def _closed_hand(m: mujoco.MjModel) -> np.ndarray:
    """qpos with the gripper closed by MuJoCo itself (its servo, the linkage's constraints)."""
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home"))
    d.ctrl[:7] = d.qpos[ROBOT.qpos_adr[:7]]
    d.ctrl[6] = ROBOT.spec.upper[6]
    for _ in range(1500):
        mujoco.mj_step(m, d)
    return d.qpos.copy()


def test_the_table_clearance_of_a_configuration_is_mujocos_own_contact_depth() -> None:
    """The commanded configuration's depth into the table (the protective stop's measure) is
    the penetration MuJoCo's collision finds for the same q, geom for geom, the gripper open
    and closed, while the arm is clear of it and as it goes in; through the slab it keeps
    counting from the top, where MuJoCo's depth turns to the nearer bottom face."""
    clearance = Clearance.of_model(ROBOT.mjm, ARM, KIN, ROBOT.spec.names[6])
    assert clearance is not None and "left_pad" in clearance.geom_names
    # every fixed geom the arm can touch, nothing that moves (the cube)
    assert clearance.obstacle_names == ("floor", "table_top", "pedestal_geom")
    slab = clearance.half[clearance.obstacle_names.index("table_top"), 2]
    m, d = ROBOT.mjm, mujoco.MjData(ROBOT.mjm)
    table = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "table_top")
    qs = np.array(
        [ROBOT.spec.home[:6] + [0, s, 0, 0, 0, 0] for s in (0, 0.2, 0.25, 0.27, 0.3, 0.4)]
    )
    closed = _closed_hand(m)
    compared = 0
    for hand in (m.qpos0, closed):
        opening = np.full(len(qs), hand[ROBOT.qpos_adr[6]])
        depth, geom, obstacle = clearance.depth(qs, opening)
        for q, ours, g, o in zip(qs, depth, geom, obstacle, strict=True):
            d.qpos[:] = hand
            d.qpos[ROBOT.qpos_adr[:6]] = q
            mujoco.mj_forward(m, d)
            hits: dict[str, float] = {}  # the arm's and gripper's deepest (not the cube's)
            for c in d.contact[: d.ncon]:
                name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, int(sum(c.geom) - table))
                if table in c.geom and name in clearance.geom_names:
                    hits[name] = min(c.dist, hits.get(name, np.inf))
            if not hits:
                assert ours < 0  # above the table
                continue
            name = min(hits, key=hits.__getitem__)
            if ours < 2 * slab:  # within the slab: MuJoCo's depth is the same
                assert ours == pytest.approx(-hits[name], abs=2e-4)  # 1e-6 open, 0.2 mm closed
                assert clearance.geom_names[g] == name
                assert clearance.obstacle_names[o] == "table_top"
                compared += 1
        assert depth[0] < -0.15 and depth[-1] > 0.05  # home is clear; the last goes through
        assert np.all(np.diff(depth) > 0)
    assert compared >= 3
    # closing lowers the 2F-140's pads by 2.4 cm: the same arm pose reaches deeper closed
    shut = clearance.depth(qs[-1:], np.array([closed[ROBOT.qpos_adr[6]]]))[0][0]
    assert shut - clearance.depth(qs[-1:], np.zeros(1))[0][0] > 0.02


def test_a_model_that_is_not_the_dh_chain_is_refused() -> None:
    spec = mujoco.MjSpec.from_file(str(SCENE_XML))
    spec.body("forearm_link").quat = [0.9999, 0.01, 0, 0]  # an elbow axis not parallel
    with pytest.raises(NotDH, match="DH chain"):
        URKinematics.from_model(spec.compile(), ARM)


def test_each_capsule_against_each_fixed_obstacle_is_mujocos_own_contact_depth() -> None:
    """Every arm capsule against the floor, the table and the pedestal at random commanded
    configurations: wherever MuJoCo's collision finds them touching and the capsule's axis
    stays outside, the clearance is never short of MuJoCo's penetration, measured along the
    whole axis (a forearm across the table's edge, not only its ends), and is the very same
    to 1e-9 m but where the space under a table top counts as table (clearance.py says why);
    once the axis is in, it reads at least the capsule's radius (4.5 cm or more: a stop)."""
    full = Clearance.of_model(ROBOT.mjm, ARM, KIN, ROBOT.spec.names[6])
    assert full is not None
    m, d = ROBOT.mjm, mujoco.MjData(ROBOT.mjm)
    qs = np.array(ROBOT.spec.home[:6]) + np.random.default_rng(2).uniform(-1.8, 1.8, (600, 6))
    compared = same = 0
    for o, obstacle in enumerate(full.obstacle_names):
        oid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, obstacle)
        for c0, c1 in full.segments:
            name = full.geom_names[full.geom[c0]]
            one = dataclasses.replace(
                full,
                points=full.points[:, [c0, c1]],
                frame=full.frame[[c0, c1]],
                radius=full.radius[[c0, c1]],
                geom=full.geom[[c0, c1]],
                segments=np.array([[0, 1]]),
                to_obstacle=full.to_obstacle[o : o + 1],
                half=full.half[o : o + 1],
                obstacle_names=(obstacle,),
            )
            ours = one.depth(qs)[0]
            gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
            for q, depth in zip(qs[ours > -0.01], ours[ours > -0.01], strict=True):
                d.qpos[:] = m.qpos0
                d.qpos[ROBOT.qpos_adr[:6]] = q
                mujoco.mj_kinematics(m, d)
                mujoco.mj_collision(m, d)
                dist = [c.dist for c in d.contact[: d.ncon] if set(c.geom) == {gid, oid}]
                if not dist:
                    continue
                if -min(dist) < full.radius[c0]:  # the axis outside: never short of MuJoCo
                    assert depth >= -min(dist) - 1e-9, (obstacle, name, q)
                    same += abs(depth + min(dist)) < 1e-9
                    compared += 1
                else:
                    assert depth >= full.radius[c0] - 1e-9, (obstacle, name, q)
    print(f"{compared} capsule contacts, {same} of MuJoCo's very depth")
    assert compared > 100 and same > 0.6 * compared  # the rest: under a top (the column)


def test_the_depth_changes_no_faster_than_the_reach_the_watch_skips_by() -> None:
    """The clearance watch measures a world again only once its joints moved enough to close
    its last clearance (`reach` · |dq| + `finger_reach` · |d opening|): at random poses and
    steps, the depth never changes by more than that bound, and somewhere it comes within a
    few times of it (a bound far too loose would have the watch measure for nothing)."""
    clearance = Clearance.of_model(ROBOT.mjm, ARM, KIN, ROBOT.spec.names[6])
    assert clearance is not None
    rng = np.random.default_rng(3)
    q = np.array(ROBOT.spec.home[:6]) + rng.uniform(-1.5, 1.5, (3000, 6))
    dq = rng.normal(0.0, 0.03, (3000, 6)) * (rng.random((3000, 1)) < 0.5)  # some steps: fingers
    opening = rng.uniform(0.0, 0.7, 3000)
    step = rng.normal(0.0, 0.05, 3000)
    after = np.clip(opening + step, 0.0, 0.7)
    before = clearance.depth(q, opening)[0]
    moved = clearance.depth(q + dq, after)[0]
    bound = np.abs(dq) @ clearance.reach + clearance.finger_reach * np.abs(after - opening)
    assert (np.abs(moved - before) <= bound + 1e-12).all()
    assert (np.abs(moved - before) / bound).max() > 0.3  # met within a few times somewhere
