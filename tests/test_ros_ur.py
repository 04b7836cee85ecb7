"""`/robot_description` and the tf tree, judged by independent implementations: the URDF is
parsed by urdf_parser_py (ROS's Python URDF parser) and urdfdom's `check_urdf`, and its forward
kinematics, computed here from the parsed joints, is compared with MuJoCo's body poses, as are the
frame tree's transforms. What a ROS 2 node sees on `/tf` is judged in tests/test_ros_node.py.
"""

from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest
from urdf_parser_py.urdf import URDF

from service.core.sim.robot import load_robot
from service.surfaces.ros import urdf
from service.surfaces.ros.tf_frames import FrameTree
from tests.conftest import JOINTS

ROBOT = load_robot()
TF = "tf2_msgs/msg/TFMessage"


# -- forward kinematics over the parsed URDF -------------------------------------------------


def _rpy_matrix(rpy: list[float]) -> np.ndarray:
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _axis_angle(axis: list[float], angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx


def _homogeneous(rot: np.ndarray, pos: Any) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, pos
    return out


def urdf_fk(robot: URDF, q: dict[str, float]) -> dict[str, np.ndarray]:
    """World pose (4x4) of every link; mimic joints follow their leader."""
    poses = {robot.get_root(): np.eye(4)}
    pending = list(robot.joints)
    while pending:
        joint = next(j for j in pending if j.parent in poses)
        pending.remove(joint)
        origin = joint.origin
        local = _homogeneous(_rpy_matrix(origin.rpy), origin.xyz)
        if joint.type != "fixed":
            if joint.mimic is not None:
                value = q[joint.mimic.joint] * joint.mimic.multiplier + joint.mimic.offset
            else:
                value = q[joint.name]
            local = local @ _homogeneous(_axis_angle(joint.axis, value), np.zeros(3))
        poses[joint.child] = poses[joint.parent] @ local
    return poses


def mujoco_poses(q: dict[str, float]) -> mujoco.MjData:
    """MuJoCo's kinematics at the same configuration (mimic joints set by their multipliers)."""
    mjm = ROBOT.mjm
    data = mujoco.MjData(mjm)
    mujoco.mj_resetDataKeyframe(mjm, data, ROBOT.home_key)
    for name, value in q.items():
        data.joint(name).qpos[0] = value
    for e in range(mjm.neq):
        follower, leader = mjm.eq_obj1id[e], mjm.eq_obj2id[e]
        data.qpos[mjm.jnt_qposadr[follower]] = (
            mjm.eq_data[e, 1] * data.qpos[mjm.jnt_qposadr[leader]]
        )
    mujoco.mj_kinematics(mjm, data)
    return data


CONFIGS = [
    dict(zip(JOINTS, ROBOT.spec.home.tolist(), strict=True)),
    dict(zip(JOINTS, [0.4, -1.1, 1.9, -2.2, -1.2, 0.7, 0.35], strict=True)),
    dict(zip(JOINTS, [-2.5, -0.3, -2.8, 1.1, 2.4, -3.0, 0.7], strict=True)),
]


_HALF_TURN_Z = np.diag([-1.0, -1.0, 1.0])
UR_ALIASES = {
    # ur_description: base_link -> base is a half turn about z; tool0 has the flange face's
    # position and wrist_3_link's axes (z out of the tool)
    "base_link": lambda d: (d.body("base").xpos, d.body("base").xmat.reshape(3, 3) @ _HALF_TURN_Z),
    "tool0": lambda d: (d.site("flange").xpos, d.body("wrist_3_link").xmat.reshape(3, 3)),
}


@pytest.mark.parametrize("q", CONFIGS)
def test_urdf_forward_kinematics_matches_mujoco(q: dict[str, float]) -> None:
    robot = URDF.from_xml_string(urdf.generate(ROBOT.mjm, ROBOT.spec))
    poses = urdf_fk(robot, q)
    data = mujoco_poses(q)
    mjm = ROBOT.mjm
    checked = 0
    for link in robot.links:
        if link.name == "world":
            continue
        body = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_BODY, link.name)
        if link.name in UR_ALIASES:  # ur_description's names: defined from other frames
            pos, rot = UR_ALIASES[link.name](data)
        elif body >= 0:
            pos, rot = data.xpos[body], data.xmat[body].reshape(3, 3)
        else:
            site = data.site(link.name)
            pos, rot = site.xpos, site.xmat.reshape(3, 3)
        np.testing.assert_allclose(poses[link.name][:3, 3], pos, atol=1e-9, err_msg=link.name)
        np.testing.assert_allclose(poses[link.name][:3, :3], rot, atol=1e-9, err_msg=link.name)
        checked += 1
    assert checked == mjm.nbody - 2 + 3 + 2  # all bodies but world and the cube; 3 sites; 2 UR


def test_urdf_declares_joints_limits_mimics_and_visuals() -> None:
    robot = URDF.from_xml_string(urdf.generate(ROBOT.mjm, ROBOT.spec))
    joints = {j.name: j for j in robot.joints}
    for spec in ROBOT.spec.joints:
        j = joints[spec.name]
        assert j.type == "revolute"
        assert (j.limit.lower, j.limit.upper) == (spec.lower, spec.upper)
        assert (j.limit.effort, j.limit.velocity) == (spec.effort_limit, spec.velocity_limit)
    assert joints["shoulder_pan_joint"].axis == [0, 0, 1.0]
    assert joints["right_outer_knuckle_joint"].mimic.joint == "finger_joint"
    assert joints["right_outer_knuckle_joint"].mimic.multiplier == -1
    links = {link.name: link for link in robot.links}
    assert "cube" not in links and {"flange", "pinch"} <= set(links)
    shapes = {type(v.geometry).__name__ for link in robot.links for v in link.visuals}
    assert shapes == {"Box", "Cylinder", "Sphere"}  # capsules as a cylinder and two spheres
    assert links["upper_arm_link"].inertial.mass == pytest.approx(13.051)


def test_urdfdom_parses_the_urdf(tmp_path: Path) -> None:
    """urdfdom (the C++ parser behind RViz's RobotModel and robot_state_publisher) reads it
    and finds the same tree: root `world`, every link once."""
    if shutil.which("check_urdf") is None:
        pytest.skip("check_urdf missing (apt-get install liburdfdom-tools; scripts/dev.py does)")
    path = tmp_path / "armfleet.urdf"
    path.write_text(urdf.generate(ROBOT.mjm, ROBOT.spec))
    out = subprocess.run(["check_urdf", str(path)], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "Successfully Parsed XML" in out.stdout and "root Link: world" in out.stdout
    robot = URDF.from_xml_string(path.read_text())
    lines = [line.strip() for line in out.stdout.splitlines()]
    named = [line.split(":  ")[-1] for line in lines if line.startswith("child(")]
    assert sorted(named) == sorted(link.name for link in robot.links if link.name != "world")


def test_frame_tree_gives_mujoco_body_poses_back() -> None:
    tree = FrameTree(ROBOT.mjm)
    q = CONFIGS[1]
    data = mujoco_poses(q)
    pos, quat = tree.moving(data.xpos[None], data.xquat[None])
    world = {"world": np.eye(4)}
    for t in tree.static:
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, np.array(t.quat))
        world[t.child] = _homogeneous(rot.reshape(3, 3), t.pos)
    links = dict(zip(tree.moving_children, range(len(pos[0])), strict=True))
    pending = {t.child: t.parent for t in tree.static} | dict(
        zip(tree.moving_children, tree.moving_parents, strict=True)
    )
    done: dict[str, np.ndarray] = {"world": np.eye(4)}
    while pending:
        child = next(c for c, p in pending.items() if p in done)
        parent = pending.pop(child)
        if child in links:
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, quat[0, links[child]])
            local = _homogeneous(rot.reshape(3, 3), pos[0, links[child]])
        else:
            local = world[child]
        done[child] = done[parent] @ local
    for name in ("wrist_3_link", "right_inner_finger", "pinch"):
        body = mujoco.mj_name2id(ROBOT.mjm, mujoco.mjtObj.mjOBJ_BODY, name)
        expected = data.xpos[body] if body >= 0 else data.site(name).xpos
        np.testing.assert_allclose(done[name][:3, 3], expected, atol=1e-9)
