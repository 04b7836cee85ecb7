"""The armfleet_ros node's parts that need no ROS: message checks, Python 3.10, and keeping a
sourced ROS shell's PYTHONPATH out of armfleet's own interpreter."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from clients import ros_rules
from service.core.process import pythonpath
from tests.conftest import JOINTS, ROOT
from tests.pythons import interpreter

NODE_SRC = ROOT / "packaging" / "armfleet-ros"
sys.path.insert(0, str(NODE_SRC))
from armfleet_ros import convert, namespaces  # noqa: E402


def test_joint_state_rules() -> None:
    assert convert.joint_state_targets(JOINTS, ["finger_joint"], [0.7]) == {"finger_joint": 0.7}
    assert list(convert.joint_state_targets(JOINTS, [], [0.0] * 7)) == JOINTS
    cases = {
        "empty": ([], []),
        "length_mismatch": (["elbow_joint"], [0.1, 0.2]),
        "unknown_joint": (["nope"], [0.1]),
        "duplicate_joint": (["elbow_joint", "elbow_joint"], [0.1, 0.2]),
        "not_finite": (["elbow_joint"], [float("inf")]),
    }
    for kind, (names, values) in cases.items():
        with pytest.raises(convert.BadMessage) as err:
            convert.joint_state_targets(JOINTS, names, values)
        assert err.value.kind == kind


def test_graph_names_open_their_group_once() -> None:
    """Which group of which namespace a graph name opens (the node's own use of it is judged
    on a real ROS in test_ros_node.py::test_a_world_namespace_opens_at_first_use)."""
    made: list[tuple[str, int, str]] = []
    gripper = ros_rules.GRIPPER_ACTION
    groups = {gripper: (gripper,), "sim": ("get_entities", "get_entity_state")}
    served = {"": 0, "/world_2": 2, "/world_10": 10}
    spaces = namespaces.Namespaces(None, served, groups, lambda *a: made.append(a))
    spaces.open_all("")
    assert made == [("", 0, "topics"), ("", 0, gripper), ("", 0, "sim")]
    names = [
        "/joint_commands",  # the root's: open already
        "/world_2/joint_states",
        "/world_2/joint_commands",  # the same group: once
        f"/world_2/{gripper}/_action/feedback",
        "/world_2/get_entity_state",
        "/world_2/get_entity_statex",  # not a service of the group: a topic
        "/world_1/joint_states",  # not served
        "/world_10",  # the namespace itself names nothing in it
        "/world_10/robotiq_gripper_controller",  # above the action's name: a topic
    ]
    wanted = spaces.wanted(names)
    assert wanted == [
        ("/world_2", "topics"),
        ("/world_2", gripper),
        ("/world_2", "sim"),
        ("/world_10", "topics"),
    ]
    for ns, group in wanted:
        assert spaces.open(ns, group)
    assert not spaces.open("/world_2", "sim") and not spaces.open("/world_1", "topics")
    assert made[3:] == [(ns, served[ns], group) for ns, group in wanted]
    assert spaces.wanted(names) == [] and spaces.open_namespaces() == 3


def test_forward_and_trajectory_bodies() -> None:
    assert list(convert.forward_targets(JOINTS, [0.1] * 6)) == JOINTS[:6]
    with pytest.raises(convert.BadMessage, match="length_mismatch"):
        convert.forward_targets(JOINTS, [0.1] * 7)
    dur = SimpleNamespace(sec=1, nanosec=500_000_000)
    pt = SimpleNamespace(positions=[0.1], velocities=[], accelerations=[], time_from_start=dur)
    traj = SimpleNamespace(joint_names=["elbow_joint"], points=[pt])
    body = convert.trajectory_body(traj, goal_time=dur)
    assert body["points"][0]["time_from_start"] == 1.5 and body["goal_time_tolerance"] == 1.5


@pytest.mark.skipif(interpreter((3, 10)) is None, reason="no Python 3.10 on this machine")
def test_node_code_is_python_310() -> None:
    """Humble's Python: every module of the node compiles there (the client's are checked by
    tests/test_client_dist.py)."""
    files = sorted(str(p) for p in (NODE_SRC / "armfleet_ros").glob("*.py"))
    files.append(str(NODE_SRC / "setup.py"))
    compile_all = (
        "import sys, py_compile\nfor f in sys.argv[1:]: py_compile.compile(f, doraise=True)"
    )
    done = subprocess.run(
        [str(interpreter((3, 10))), "-B", "-c", compile_all, *files], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr


def test_ros_pythonpath_is_kept_out(tmp_path: Path) -> None:
    ros = tmp_path / "opt" / "ros" / "humble"
    site = ros / "lib" / "python3.10" / "site-packages"
    (site / "rclpy").mkdir(parents=True)
    same = tmp_path / "venv" / "lib" / f"python3.{sys.version_info[1]}" / "site-packages"
    (same / "rclpy").mkdir(parents=True)
    prefixes = [str(ros)]
    assert pythonpath.foreign(str(site), prefixes)  # another Python's
    assert pythonpath.foreign(str(same), [])  # this Python's version, but ROS's rclpy
    assert pythonpath.foreign(str(ros / "local" / "lib"), prefixes)  # under an ament prefix
    assert not pythonpath.foreign(str(ROOT), prefixes)  # a checkout put there on purpose
    env = {"PYTHONPATH": f"{ROOT}:{site}", "AMENT_PREFIX_PATH": str(ros), "PATH": "/usr/bin:/bin"}
    code = (
        "import os, sys, service; print(os.environ['PYTHONPATH']);"
        "print(os.environ['ARMFLEET_ROS2_PYTHONPATH']);"
        f"print({str(site)!r} in sys.path)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tmp_path
    )
    assert done.stdout.splitlines() == [str(ROOT), f"{ROOT}:{site}", "False"], done.stderr


def test_the_rulebook_both_faces_apply() -> None:
    """clients/ros_rules.py, which rosbridge and the node both import: result codes, the
    gripper's reached / stalled rule, and a counter that counts all but logs a kind once."""
    assert [ros_rules.result_code(r) for r in (None, "cancelled", "path_tolerance")] == [0, 0, -4]
    assert [ros_rules.result_code(r) for r in ("goal_tolerance", "preempted")] == [-5, -1]
    assert ros_rules.error_string("reset", "world 3 was reset") == "reset: world 3 was reset"
    watch = ros_rules.FingerWatch(0.5)
    assert watch.verdict(0.0, 0.1, 1.0) is None  # moving
    assert watch.verdict(0.1, 0.2, 0.0) is None  # stopped, not for long
    assert watch.verdict(0.1 + ros_rules.STALL_TIMEOUT_S, 0.2, 0.0) == "stalled"
    assert ros_rules.FingerWatch(0.5).verdict(0.0, 0.495, 0.0) == "reached"
    assert watch.taken_over(0.6) and not watch.taken_over(0.5 + 1e-7)
    with pytest.raises(ros_rules.GoalRejected, match="max_effort must be >= 0"):
        ros_rules.gripper_goal(0.3, -1.0)
    lines: list[str] = []
    counter = ros_rules.RefusalCounter("armfleet_ros", lines.append)
    for _ in range(3):
        counter.report("empty", "/joint_commands", "position: position is empty")
    assert counter.counts() == {"empty": 3} and len(lines) == 1
    assert lines == ["armfleet_ros: refused on /joint_commands: empty: position: position is empty"]
