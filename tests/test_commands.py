"""Target arithmetic on its own: the seed's buttons, clamping and refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.errors import BadCommand
from service.core.sim import arithmetic as commands
from service.core.sim.robot import load_robot

SPEC = load_robot().spec
HOME = SPEC.home


def test_increment_is_clamped_to_gripper_range():
    row = HOME.copy()
    for _ in range(9):
        update = commands.increment(SPEC, row, {6: 0.1})
        row = update.target
    assert row[6] == 0.7 and update.clamped == ["finger_joint"]
    for _ in range(7):
        row = commands.increment(SPEC, row, {6: -0.1}).target
    assert row[6] == 0.0  # exactly: presses land on decimals, like the seed's round(x, 2)


def test_increment_touches_only_the_named_joints():
    update = commands.increment(SPEC, HOME, {2: 0.1, 5: -0.2})
    expected = HOME.copy()
    expected[2] += 0.1
    expected[5] -= 0.2
    np.testing.assert_allclose(update.target, expected)
    assert update.clamped == []


def test_delta_over_a_full_turn_is_refused_before_anything_changes():
    with pytest.raises(BadCommand) as err:
        commands.check_deltas(SPEC, {0: 0.1, 1: 2 * math.pi + 0.01})
    assert err.value.field == "delta.shoulder_lift_joint"


def test_absolute_targets_clamp_and_report_each_joint_that_hit_a_limit():
    update = commands.replace_targets(SPEC, HOME, {2: 4.0, 6: -1.0, 0: 1.0})
    assert update.target[2] == pytest.approx(math.pi)
    assert update.target[6] == 0.0 and update.target[0] == 1.0
    assert sorted(update.clamped) == ["elbow_joint", "finger_joint"]


@pytest.mark.parametrize(
    ("values", "field"),
    [
        ({"elbow": 1.0}, "name.elbow"),
        ({"9": 1.0}, "name.9"),
        ({"elbow_joint": float("nan")}, "name.elbow_joint"),
        ({"elbow_joint": "1"}, "name.elbow_joint"),
        ({"elbow_joint": True}, "name.elbow_joint"),
        ({}, "name"),
    ],
)
def test_joint_references_and_values_are_checked(values, field):
    with pytest.raises(BadCommand) as err:
        commands.resolve_joints(SPEC, values, "name")
    assert err.value.field == field


def test_joints_resolve_by_name_index_or_digit_string():
    assert commands.resolve_joints(SPEC, {"finger_joint": 1, 2: 0.5, "3": 0.25}, "x") == {
        6: 1.0,
        2: 0.5,
        3: 0.25,
    }
