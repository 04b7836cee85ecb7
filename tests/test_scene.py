"""service/core/sim/scene.py: the drawable scene is the compiled model's visible geoms, nothing
else."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from mjcf import ROBOT_XML, SCENE_XML
from service.core.sim.scene import VISIBLE_GROUPS, describe


@pytest.fixture(scope="module")
def mjm() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(SCENE_XML))


def test_every_visible_geom_is_described_with_its_compiled_values(mjm):
    scene = describe(mjm)
    visible = [g for g in range(mjm.ngeom) if mjm.geom_group[g] in VISIBLE_GROUPS]
    assert [g["id"] for g in scene["geoms"]] == visible
    assert scene["skipped"] == 0 and scene["nbody"] == mjm.nbody
    for g in scene["geoms"]:
        i = g["id"]
        assert g["body"] == mjm.geom_bodyid[i]
        np.testing.assert_allclose(g["size"], mjm.geom_size[i], atol=1e-6)
        np.testing.assert_allclose(g["pos"], mjm.geom_pos[i], atol=1e-6)
        np.testing.assert_allclose(g["quat"], mjm.geom_quat[i], atol=1e-6)
    # The collision shapes (group 3) are not drawn over the visual ones.
    assert not any(n["name"].endswith("_collision") for n in scene["geoms"])


def test_the_work_cell_is_all_there(mjm):
    scene = describe(mjm)
    bodies = {b["name"]: b["id"] for b in scene["bodies"]}
    drawn = {g["body"] for g in scene["geoms"]}
    # Pedestal, arm links, gripper links and pads, the cube all have something drawn.
    for body in ("pedestal", "base", "upper_arm_link", "wrist_3_link", "gripper_base", "cube"):
        assert bodies[body] in drawn, body
    for body in ("left_inner_finger", "right_inner_finger", "left_outer_knuckle"):
        assert bodies[body] in drawn, body
    names = {g["name"]: g for g in scene["geoms"]}
    assert names["floor"]["type"] == "plane" and names["table_top"]["type"] == "box"
    assert names["cube_geom"]["rgba"] == pytest.approx([0.85, 0.2, 0.2, 1.0])
    assert {g["type"] for g in scene["geoms"]} == {"plane", "box", "cylinder", "capsule"}


def test_a_changed_model_changes_the_description(tmp_path):
    """The page follows the MJCF: a new geom shows up with no code touched."""
    (tmp_path / ROBOT_XML.name).write_text(ROBOT_XML.read_text())
    variant = tmp_path / "scene.xml"
    variant.write_text(
        SCENE_XML.read_text().replace(
            "</worldbody>",
            '<geom name="marker" type="sphere" size="0.04" pos="0 1 1" rgba="0 1 0 1"/>'
            "</worldbody>",
        )
    )
    model = mujoco.MjModel.from_xml_path(str(variant))
    marker = next(g for g in describe(model)["geoms"] if g["name"] == "marker")
    assert marker["type"] == "sphere" and marker["size"][0] == pytest.approx(0.04)
    assert marker["body"] == 0 and marker["pos"] == pytest.approx([0, 1, 1])
