"""A cell that lets bodies at rest sleep (<flag sleep="enable"/>): the example bin-picking cell
with the flag set (the shipped example keeps its parts awake, so that restores stay bit-exact).

The native engine honours it (a persistent batch: MuJoCo keeps who sleeps in one MjData per
world); everything else sharing the model steps every body. Sleeping must not change where the
parts rest, and anything that touches a sleeping part (a pose written, a part landing on it)
must wake it.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import mujoco
import numpy as np
import pytest

from mjcf import MJCF_DIR
from service.core.sim.batch import StateWrite
from service.core.sim.robot import load_robot
from service.engines.native import NativeBatch
from tests.test_model import solve_ik

EXAMPLE = MJCF_DIR / "examples" / "bin_picking.xml"
AWAKE_OPTION = '<option timestep="0.002" integrator="implicitfast"/>'


def _sleeping_copy() -> Path:
    """The example cell with `<flag sleep="enable"/>`, in a folder of its own (the arm's file
    is found by name, wherever the cell lies)."""
    text = EXAMPLE.read_text()
    flagged = text.replace(AWAKE_OPTION, AWAKE_OPTION[:-2] + '><flag sleep="enable"/></option>')
    assert flagged != text, "the example's <option> line changed: update AWAKE_OPTION"
    path = Path(tempfile.mkdtemp(prefix="armfleet-sleep-")) / "bin_picking_sleeping.xml"
    path.write_text(flagged)
    return path


SLEEPY = _sleeping_copy()
SETTLE = 180  # ticks (3 s at 60 Hz): the parts come to rest and fall asleep


def _qpos_adr(batch: NativeBatch, joint: str) -> int:
    mjm = batch.robot.mjm
    return int(mjm.jnt_qposadr[mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, joint)])


@pytest.fixture(scope="module")
def settled() -> tuple[NativeBatch, NativeBatch]:
    """The example cell in 2 worlds, sleeping and (the same cell, sleep off) awake, settled."""
    asleep = NativeBatch(2, model_path=SLEEPY)
    awake = NativeBatch(2, robot=load_robot(EXAMPLE))
    for b in (asleep, awake):
        b.step(SETTLE)
    return asleep, awake


def test_a_cell_asking_for_sleep_sleeps_in_the_native_batch_only(settled):
    asleep, awake = settled
    assert asleep.robot.sleep and not load_robot().sleep and not load_robot(EXAMPLE).sleep
    # The shared model steps every body (warp, the camera renderer, the kinematics use it).
    assert not asleep.robot.mjm.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP
    for b in (asleep, awake):
        b.capacity_usage()  # binds the contact counts, read from the next call on
        b.step(1)
    # Asleep, the parts resting in the bin have no contacts computed; awake, they have.
    assert asleep.capacity_usage()[0] == 0
    assert awake.capacity_usage()[0] > 0


def test_sleeping_does_not_move_where_the_parts_rest(settled):
    asleep, awake = settled
    for joint in ("part_box_joint", "part_cylinder_joint", "part_ball_joint"):
        a = _qpos_adr(asleep, joint)
        diff = np.abs(asleep.qpos()[:, a : a + 3] - awake.qpos()[:, a : a + 3]).max()
        assert diff < 1e-3, (joint, diff)


def test_a_written_pose_wakes_a_sleeping_part_in_that_world_only():
    batch = NativeBatch(2, model_path=SLEEPY)
    batch.step(SETTLE)
    a = _qpos_adr(batch, "part_ball_joint")
    rest = batch.qpos()[:, a + 2].copy()
    batch.write_state(StateWrite(world=0, field="qpos", index=(a + 2,), values=(rest[0] + 0.2,)))
    batch.step(6)  # 0.1 s of free fall, n steps of dt: velocity first, g dt^2 n (n + 1) / 2
    n = 6 * batch.substeps
    z = batch.qpos()[:, a + 2]
    assert z[0] == pytest.approx(
        rest[0] + 0.2 - 9.81 * batch.physics_dt**2 * n * (n + 1) / 2, abs=1e-3
    )
    assert z[1] == rest[1]  # the other world's ball still sleeps where it was


def test_a_part_landing_on_a_sleeping_part_wakes_it_and_rests_on_it():
    batch = NativeBatch(1, model_path=SLEEPY)
    batch.step(SETTLE)
    box, cyl = _qpos_adr(batch, "part_box_joint"), _qpos_adr(batch, "part_cylinder_joint")
    box_before = batch.qpos()[0, box : box + 3].copy()
    above = (*box_before[:2], box_before[2] + 0.15, 1.0, 0.0, 0.0, 0.0)  # upright, 15 cm up
    batch.write_state(StateWrite(world=0, field="qpos", index=range(cyl, cyl + 7), values=above))
    batch.step(90)
    q = batch.qpos()[0]
    # On the box's top face (box half-height 0.025, cylinder half-height 0.03), not through it.
    assert q[cyl + 2] == pytest.approx(box_before[2] + 0.025 + 0.03, abs=0.003)
    assert np.abs(q[box : box + 3] - box_before).max() < 0.003


def test_state_round_trip_and_reset_on_a_sleeping_batch():
    batch = NativeBatch(2, model_path=SLEEPY)
    batch.step(SETTLE)
    saved = batch.get_state()
    batch.step(60)
    first = batch.qpos()
    batch.set_state(saved)
    batch.step(60)
    np.testing.assert_array_equal(batch.qpos(), first)
    batch.reset(np.array([1]))
    home = batch.robot.mjm.key_qpos[batch.robot.home_key]
    np.testing.assert_array_equal(batch.qpos()[1], home)


def test_a_snapshot_restored_into_a_fresh_batch_goes_on_within_micrometres():
    """Who sleeps is not in the state rows: restored elsewhere, a sleeping part starts awake and
    falls asleep again (the guide says so); the worlds stay within micrometres, not bits."""
    first = NativeBatch(2, model_path=SLEEPY)
    first.step(SETTLE)
    saved = first.get_state()
    first.step(120)
    fresh = NativeBatch(2, model_path=SLEEPY)
    fresh.set_state(saved)
    fresh.step(120)
    assert np.abs(fresh.qpos() - first.qpos()).max() < 1e-4


@pytest.mark.parametrize("sleep", [True, False], ids=["asleep", "awake"])
def test_the_gripper_picks_a_sleeping_part_as_an_awake_one(sleep):
    """The pads closing on the box asleep in the bin wake it: it is lifted 10 cm and held, as
    when nothing sleeps (the grasp of tests/test_model.py, on the cell's box)."""
    robot = dataclasses.replace(load_robot(SLEEPY), sleep=sleep)
    batch = NativeBatch(1, robot=robot)
    batch.step(SETTLE)
    mjm = robot.mjm
    data = mujoco.MjData(mjm)
    data.qpos[:] = batch.qpos()[0]
    mujoco.mj_kinematics(mjm, data)
    box = mjm.body("part_box").id
    start = data.xpos[box].copy()
    rot = data.site("flange").xmat.reshape(3, 3).copy()
    home = data.qpos[:6].copy()
    q_grasp = solve_ik(mjm, data, home, start + np.array([0.0, 0.0, 0.02]), rot)
    q_lift = solve_ik(mjm, data, q_grasp, start + np.array([0.0, 0.0, 0.12]), rot)

    def move(q_from, q_to, seconds, finger):
        n = round(seconds * batch.control_hz)
        for k in range(n):
            s = min(1.0, 1.5 * (k + 1) / n)
            f = finger[0] + s * (finger[1] - finger[0])
            batch.apply_targets(np.array([0]), np.r_[q_from + s * (q_to - q_from), f][None])
            batch.step(1)

    move(home, q_grasp, 1.2, (0.0, 0.0))
    move(q_grasp, q_grasp, 0.8, (0.0, 0.7))
    move(q_grasp, q_lift, 1.2, (0.7, 0.7))
    rise = []
    for _ in range(120):  # 2 s held
        batch.step(1)
        rise.append(batch.snapshot().bodies.get()[0][0, box, 2] - start[2])
    assert min(rise) >= 0.095, min(rise)
    assert max(rise) - min(rise) <= 0.01
    assert batch.snapshot().faults[0] == 0
