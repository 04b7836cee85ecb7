"""rosbridge v2 actions (send_action_goal, cancel_action_goal, action_feedback, action_result),
judged by the real clients: roslibpy 2.1's ActionClient and roslib.js 2.x's Action (Node).
Goal with feedback and result, cancel (and roslib.js's cancelAllGoals), bad goals; rosapi
lists the actions.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest
import roslibpy

from tests.conftest import JOINTS, Server, serve, wait_for

FJT = "control_msgs/action/FollowJointTrajectory"
ARM = JOINTS[:6]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    log_dir = tmp_path_factory.mktemp("rosbridge_actions")
    extra = ("--ros2-worlds", "1", "--engine", "mujoco")  # starts in seconds
    with serve(worlds=2, extra_args=extra, log_dir=log_dir) as srv:
        yield srv


def _goal(positions: list[float], seconds: float) -> roslibpy.Goal:
    stamp = {"sec": int(seconds), "nanosec": round((seconds % 1) * 1e9)}
    point = {"positions": positions, "time_from_start": stamp}
    return roslibpy.Goal({"trajectory": {"joint_names": ARM, "points": [point]}})


class Outcome:
    """roslibpy's three callbacks, collected."""

    def __init__(self) -> None:
        self.feedback: list[dict[str, Any]] = []
        self.result: Any = None
        self.error: Any = None
        self.done = threading.Event()

    def on_result(self, result: Any) -> None:
        self.result = result
        self.done.set()

    def on_error(self, error: Any) -> None:
        self.error = error
        self.done.set()


def _send(client: roslibpy.ActionClient, goal: roslibpy.Goal) -> tuple[str, Outcome]:
    out = Outcome()
    goal_id = client.send_goal(goal, out.on_result, out.feedback.append, out.on_error)
    return goal_id, out


def test_rosapi_lists_the_actions(ros: roslibpy.Ros) -> None:
    found: list[dict[str, list[str]]] = []
    ros.get_action_servers(found.append)
    servers = wait_for(lambda: found, "rosapi/action_servers")[0]["action_servers"]
    for ns in ("", "/world_1"):
        assert f"{ns}/scaled_joint_trajectory_controller/follow_joint_trajectory" in servers
        assert f"{ns}/joint_trajectory_controller/follow_joint_trajectory" in servers
        assert f"{ns}/robotiq_gripper_controller/gripper_cmd" in servers
    assert len(servers) == 6


def test_roslibpy_goal_feedback_result(server: Server, ros: roslibpy.Ros) -> None:
    client = roslibpy.ActionClient(
        ros, "/world_1/scaled_joint_trajectory_controller/follow_joint_trajectory", FJT
    )
    wanted = [0.25, -1.45, 1.5, -1.6, -1.5, 0.3]
    _, out = _send(client, _goal(wanted, 0.8))
    assert out.done.wait(30), "no action_result"
    assert out.error is None, out.error
    assert out.result["status"] == roslibpy.GoalStatus.SUCCEEDED
    assert out.result["values"] == {"error_code": 0, "error_string": ""}
    assert len(out.feedback) >= 3
    fb = out.feedback[-1]
    assert fb["joint_names"] == ARM and len(fb["desired"]["positions"]) == 6
    target = httpx.get(f"{server.url}/v1/worlds/1/state").json()["target"]
    np.testing.assert_allclose(target[:6], wanted, atol=1e-9)


def test_roslibpy_cancel(server: Server, ros: roslibpy.Ros) -> None:
    client = roslibpy.ActionClient(ros, "/joint_trajectory_controller/follow_joint_trajectory", FJT)
    goal_id, out = _send(client, _goal([1.0, -1.0, 1.0, -1.0, -1.0, 1.0], 20.0))
    wait_for(lambda: out.feedback, "feedback of the long goal")
    client.cancel_goal(goal_id)
    assert out.done.wait(30), "no action_result after the cancel"
    assert out.result["status"] == roslibpy.GoalStatus.CANCELED
    assert "cancelled" in out.result["values"]["error_string"]
    held = httpx.get(f"{server.url}/v1/worlds/0/state").json()["target"]
    assert 0 < held[0] < 1.0


def test_roslibpy_a_broken_tolerance_or_a_newer_goal_aborts_with_its_code(
    server: Server, ros: roslibpy.Ros
) -> None:
    """The ROS 2 guide's results, which rosbridge shares: ABORTED with -4 when a path
    tolerance broke, ABORTED with -1 and the reason when a newer goal preempted the goal."""
    name = "/world_1/scaled_joint_trajectory_controller/follow_joint_trajectory"
    client = roslibpy.ActionClient(ros, name, FJT)
    far = [0.8, -1.0, 1.0, -1.0, -1.0, 0.8]
    point = {"positions": far, "time_from_start": {"sec": 1, "nanosec": 0}}
    tight = {"name": "elbow_joint", "position": 1e-4, "velocity": 0.0, "acceleration": 0.0}
    goal = {"trajectory": {"joint_names": ARM, "points": [point]}, "path_tolerance": [tight]}
    _, out = _send(client, roslibpy.Goal(goal))
    assert out.done.wait(30), "no action_result"
    assert out.result["status"] == roslibpy.GoalStatus.ABORTED, out.result
    assert out.result["values"]["error_code"] == -4
    assert out.result["values"]["error_string"].startswith("path_tolerance")
    _, first = _send(client, _goal(far, 20.0))
    wait_for(lambda: first.feedback, "feedback of the long goal")
    _, second = _send(client, _goal([0.2, -1.5, 1.5, -1.5, -1.5, 0.2], 0.5))
    assert first.done.wait(30) and second.done.wait(30), "no action_result"
    assert first.result["status"] == roslibpy.GoalStatus.ABORTED, first.result
    assert first.result["values"]["error_code"] == -1
    assert first.result["values"]["error_string"].startswith("preempted")
    assert second.result["status"] == roslibpy.GoalStatus.SUCCEEDED, second.result


@pytest.mark.parametrize(
    ("name", "kind", "goal", "why"),
    [
        ("/nope/follow_joint_trajectory", FJT, _goal([0.0] * 6, 1.0), "unknown action"),
        (
            "/robotiq_gripper_controller/gripper_cmd",
            FJT,
            _goal([0.0] * 6, 1.0),
            "control_msgs/action/GripperCommand",
        ),
        (
            "/scaled_joint_trajectory_controller/follow_joint_trajectory",
            FJT,
            _goal([0.0, 0.0, 9.0, 0.0, 0.0, 0.0], 1.0),
            "elbow_joint",
        ),
    ],
)
def test_roslibpy_bad_goals_fail_and_change_nothing(
    server: Server, ros: roslibpy.Ros, name: str, kind: str, goal: Any, why: str
) -> None:
    before = httpx.get(f"{server.url}/v1/worlds/0/state").json()["target"]
    _, out = _send(roslibpy.ActionClient(ros, name, kind), goal)
    assert out.done.wait(20), "no action_result for the bad goal"
    assert out.result is None
    assert out.error["status"] == roslibpy.GoalStatus.UNKNOWN
    assert why in out.error["values"]
    assert httpx.get(f"{server.url}/v1/worlds/0/state").json()["target"] == before


def test_roslibjs_action(server: Server, roslibjs: Any) -> None:
    name = "/world_1/joint_trajectory_controller/follow_joint_trajectory"
    seen, stderr = roslibjs("rosbridge_actions_check.mjs", server.ws_url + "/rosbridge", name)
    assert seen["ok"], (seen, stderr)
    assert seen["result"] == {"error_code": 0, "error_string": ""}
    assert seen["feedback"] >= 3 and seen["lastFeedback"]["joint_names"] == ARM
    assert "points[0].positions" in seen["bad"]  # the validator's message, status 0
    assert seen["cancelled"].startswith("GoalError: Action was canceled")  # status CANCELED
    assert seen["cancelledAll"].startswith("GoalError: Action was canceled")
