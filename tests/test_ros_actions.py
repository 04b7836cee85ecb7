"""The UR driver's actions over DDS (ROS 2 action design, rmw_cyclonedds_cpp's request/reply
convention), judged by an independent client: tests/ros2_ur_peer.py (its own Cyclone
participant, every message serialised and decoded by rosbags with control_msgs' definitions
registered from their .msg/.action text, no armfleet code).

Goal, feedback, result, status, cancel and bad goals on `follow_joint_trajectory`; the
`~/joint_trajectory` topic; the gripper closing on the cube (stalled) and opening (reached).
"""

from __future__ import annotations

import random
import uuid
from typing import Any

import httpx
import numpy as np
import pytest

from service.surfaces.ros import msgs_action as m
from tests.conftest import JOINTS, Server, wait_for
from tests.peer_stdio import UrPeer
from tests.ros2_types import serialize

FJT = "control_msgs/action/FollowJointTrajectory"
GRIPPER = "control_msgs/action/GripperCommand"
SCALED = "/world_1/scaled_joint_trajectory_controller/follow_joint_trajectory"
ARM = JOINTS[:6]
HOME_ARM = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
# the pinch point (between the pads) 10 cm above the cube's centre and 1.5 cm above it (the
# pads then clear the table), tool pointing down (IK of the model)
ABOVE_CUBE = [-0.0003, -1.5543, 1.7367, -1.7524, -1.57, -0.0003]
AT_CUBE = [-0.0003, -1.5179, 1.8529, -1.905, -1.57, -0.0003]
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6


def _dur(t: float) -> dict[str, int]:
    return {"sec": int(t), "nanosec": round((t - int(t)) * 1e9)}


def _goal(points: list[tuple[float, list[float]]], names: list[str] = ARM) -> dict[str, Any]:
    return {
        "trajectory": {
            "joint_names": names,
            "points": [{"positions": p, "time_from_start": _dur(t)} for t, p in points],
        }
    }


def _uuid() -> list[int]:
    return list(uuid.uuid4().bytes)


def _id(goal_id: list[int]) -> dict[str, list[int]]:
    return {"uuid": goal_id}


# -- layouts ----------------------------------------------------------------------------------


def test_request_reply_bytes_match_rosbags_after_the_rmw_header() -> None:
    """Our structs = rmw_cyclonedds_cpp's 16-byte header + rosbags' bytes of the ROS type."""
    rng = random.Random(5)
    goal_id = [rng.randrange(256) for _ in range(16)]
    header = (12345).to_bytes(8, "little") + (7).to_bytes(8, "little")

    def same(ours: Any, ros_type: str, value: dict[str, Any]) -> None:
        theirs = serialize(ros_type, value)
        assert bytes(ours.serialize()) == theirs[:4] + header + theirs[4:], ros_type

    same(
        m.FOLLOW_JOINT_TRAJECTORY.send_goal_request(
            12345,
            7,
            m.UUID(goal_id),
            m.FollowJointTrajectoryGoal(
                trajectory=m.JointTrajectory(
                    joint_names=ARM,
                    points=[
                        m.JointTrajectoryPoint(positions=HOME_ARM, time_from_start=m.Duration(2, 5))
                    ],
                ),
                goal_tolerance=[m.JointTolerance("elbow_joint", 0.01, 0.1, 0.0)],
                goal_time_tolerance=m.Duration(1, 0),
            ),
        ),
        f"{FJT}_SendGoal_Request",
        {
            "goal_id": {"uuid": goal_id},
            "goal": {
                "trajectory": {
                    "joint_names": ARM,
                    "points": [
                        {"positions": HOME_ARM, "time_from_start": {"sec": 2, "nanosec": 5}}
                    ],
                },
                "goal_tolerance": [
                    {"name": "elbow_joint", "position": 0.01, "velocity": 0.1, "acceleration": 0.0}
                ],
                "goal_time_tolerance": {"sec": 1, "nanosec": 0},
            },
        },
    )
    same(
        m.FOLLOW_JOINT_TRAJECTORY.get_result_response(
            12345, 7, 6, m.FollowJointTrajectoryResult(-4, "path")
        ),
        f"{FJT}_GetResult_Response",
        {"status": 6, "result": {"error_code": -4, "error_string": "path"}},
    )
    same(
        m.GRIPPER_COMMAND.send_goal_response(12345, 7, True, m.Time(3, 4)),
        f"{GRIPPER}_SendGoal_Response",
        {"accepted": True, "stamp": {"sec": 3, "nanosec": 4}},
    )
    info = m.GoalInfo(m.UUID(goal_id), m.Time(1, 2))
    same(
        m.CancelGoalResponse(12345, 7, 0, [info, info]),
        "action_msgs/srv/CancelGoal_Response",
        {
            "return_code": 0,
            "goals_canceling": [{"goal_id": {"uuid": goal_id}, "stamp": {"sec": 1, "nanosec": 2}}]
            * 2,
        },
    )
    fb = m.FOLLOW_JOINT_TRAJECTORY.feedback_message(
        m.UUID(goal_id),
        m.FollowJointTrajectoryFeedback(
            joint_names=ARM, desired=m.JointTrajectoryPoint(positions=HOME_ARM)
        ),
    )
    theirs = serialize(
        f"{FJT}_FeedbackMessage",
        {
            "goal_id": {"uuid": goal_id},
            "feedback": {"joint_names": ARM, "desired": {"positions": HOME_ARM}},
        },
    )
    assert bytes(fb.serialize()) == theirs
    status = m.GoalStatusArray([m.GoalStatus(info, 4)])
    assert bytes(status.serialize()) == serialize(
        "action_msgs/msg/GoalStatusArray",
        {
            "status_list": [
                {
                    "goal_info": {"goal_id": {"uuid": goal_id}, "stamp": {"sec": 1, "nanosec": 2}},
                    "status": 4,
                }
            ]
        },
    )


# -- a running server and an independent action client ------------------------------------------


def _state(server: Server, world: int) -> dict[str, Any]:
    return httpx.get(f"{server.url}/v1/worlds/{world}/state").json()


def test_follow_joint_trajectory_goal_feedback_result_status(
    ur_server: Server, ur_peer: UrPeer
) -> None:
    feedback_topic = f"{SCALED}/_action/feedback"
    ur_peer.ask(op="all", topic=feedback_topic, type=f"{FJT}_FeedbackMessage")
    wanted = [0.3, -1.3, 1.6, -1.8, -1.4, 0.4]
    goal_id = _uuid()
    goal = _goal([(0.5, [0.15, -1.4, 1.6, -1.7, -1.5, 0.2]), (1.0, wanted)])
    reply = ur_peer.call(SCALED, FJT, "send_goal", {"goal_id": {"uuid": goal_id}, "goal": goal})
    assert reply["accepted"] is True
    result = ur_peer.call(SCALED, FJT, "get_result", {"goal_id": {"uuid": goal_id}})
    assert result["status"] == SUCCEEDED, result
    assert result["result"] == {"error_code": 0, "error_string": ""}
    np.testing.assert_allclose(_state(ur_server, 1)["target"][:6], wanted, atol=1e-9)
    feedback = [
        f
        for f in ur_peer.ask(op="all", topic=feedback_topic, type=f"{FJT}_FeedbackMessage")
        if f["goal_id"]["uuid"] == goal_id
    ]
    assert len(feedback) >= 5  # 20 Hz over a simulated second
    last = feedback[-1]["feedback"]
    assert last["joint_names"] == ARM and len(last["actual"]["positions"]) == 6
    np.testing.assert_allclose(
        np.subtract(last["actual"]["positions"], last["desired"]["positions"]),
        last["error"]["positions"],
        atol=1e-9,
    )
    status = wait_for(
        lambda: ur_peer.ask(
            op="latest",
            topic=f"{SCALED}/_action/status",
            type="action_msgs/msg/GoalStatusArray",
            latched=True,
        ),
        "the action's status",
    )
    mine = [s for s in status["status_list"] if s["goal_info"]["goal_id"]["uuid"] == goal_id]
    assert [s["status"] for s in mine] == [SUCCEEDED]
    actions = httpx.get(f"{ur_server.url}/v1/ros").json()["dds"]["actions"]
    assert actions[SCALED] == FJT and len(actions) == 6  # 3 actions × (root, /world_1)


@pytest.mark.parametrize(
    ("goal", "why"),
    [
        (_goal([(1.0, HOME_ARM)], ["shoulder_pan_joint", "elbow"] + ARM[2:]), "elbow"),
        (_goal([(1.0, [*HOME_ARM[:5], 0.2])], [*ARM[:5], "finger_joint"]), "finger_joint"),
        (_goal([(1.0, HOME_ARM), (0.5, HOME_ARM)]), "increase"),
        (_goal([(1.0, HOME_ARM[:5])]), "positions"),
        (_goal([(1.0, [*HOME_ARM[:5], 99.0])]), "limit"),
    ],
)
def test_bad_goals_are_rejected_and_change_nothing(
    ur_server: Server, ur_peer: UrPeer, goal: dict[str, Any], why: str
) -> None:
    before = _state(ur_server, 1)["target"]
    counts = httpx.get(f"{ur_server.url}/v1/ros").json()["dds"]["rejected"]
    reply = ur_peer.call(SCALED, FJT, "send_goal", {"goal_id": {"uuid": _uuid()}, "goal": goal})
    assert reply["accepted"] is False
    assert _state(ur_server, 1)["target"] == before
    after = httpx.get(f"{ur_server.url}/v1/ros").json()["dds"]["rejected"]
    assert after["rejected_goal"] == counts.get("rejected_goal", 0) + 1


def test_cancel_stops_and_holds(ur_server: Server, ur_peer: UrPeer) -> None:
    action = "/joint_trajectory_controller/follow_joint_trajectory"  # world 0, at the root
    goal_id = _uuid()
    far = [1.5, -1.0, 1.0, -1.0, -1.0, 1.5]
    reply = ur_peer.call(
        action, FJT, "send_goal", {"goal_id": {"uuid": goal_id}, "goal": _goal([(20.0, far)])}
    )
    assert reply["accepted"]
    wait_for(lambda: _state(ur_server, 0)["target"][0] > 0.01, "the trajectory to move world 0")
    unknown = ur_peer.call(
        action, FJT, "cancel_goal", {"goal_info": {"goal_id": {"uuid": _uuid()}}}
    )
    assert unknown["return_code"] == 2 and unknown["goals_canceling"] == []
    cancel = ur_peer.call(action, FJT, "cancel_goal", {"goal_info": {"goal_id": _id(goal_id)}})
    assert cancel["return_code"] == 0
    assert [g["goal_id"]["uuid"] for g in cancel["goals_canceling"]] == [goal_id]
    result = ur_peer.call(action, FJT, "get_result", {"goal_id": {"uuid": goal_id}})
    assert result["status"] == CANCELED
    held = _state(ur_server, 0)["target"]
    assert 0 < held[0] < 1.0  # stopped part of the way
    again = ur_peer.call(action, FJT, "cancel_goal", {"goal_info": {"goal_id": {"uuid": goal_id}}})
    assert again["return_code"] == 3  # already terminated
    assert _state(ur_server, 0)["target"] == held


def test_a_newer_goal_preempts_and_joint_trajectory_topic_moves(
    ur_server: Server, ur_peer: UrPeer
) -> None:
    first = _uuid()
    slow = _goal([(20.0, [1.0, -1.0, 1.0, -1.0, -1.0, 1.0])])
    assert ur_peer.call(SCALED, FJT, "send_goal", {"goal_id": {"uuid": first}, "goal": slow})[
        "accepted"
    ]
    topic = "/world_1/scaled_joint_trajectory_controller/joint_trajectory"
    kind = "trajectory_msgs/msg/JointTrajectory"
    assert ur_peer.ask(op="matched", topic=topic, type=kind, role="reader")
    ur_peer.ask(op="publish", topic=topic, type=kind, msg=_goal([(0.5, HOME_ARM)])["trajectory"])
    result = ur_peer.call(SCALED, FJT, "get_result", {"goal_id": {"uuid": first}})
    assert result["status"] == ABORTED and "preempted" in result["result"]["error_string"]
    wait_for(
        lambda: np.allclose(_state(ur_server, 1)["target"][:6], HOME_ARM), "home via the topic"
    )
    # a newer goal of the same action preempts too (and its answer is not held up by it)
    again, newer = _uuid(), _uuid()
    for goal_id, goal in ((again, slow), (newer, _goal([(0.3, HOME_ARM)]))):
        reply = ur_peer.call(SCALED, FJT, "send_goal", {"goal_id": _id(goal_id), "goal": goal})
        assert reply["accepted"]
    result = ur_peer.call(SCALED, FJT, "get_result", {"goal_id": _id(again)})
    assert result["status"] == ABORTED and "preempted" in result["result"]["error_string"]
    assert ur_peer.call(SCALED, FJT, "get_result", {"goal_id": _id(newer)})["status"] == SUCCEEDED


def test_gripper_closes_on_the_cube_stalled_and_opens(ur_server: Server, ur_peer: UrPeer) -> None:
    action = "/robotiq_gripper_controller/gripper_cmd"
    httpx.post(f"{ur_server.url}/v1/worlds/0/reset").raise_for_status()
    arm = "/scaled_joint_trajectory_controller/follow_joint_trajectory"
    down = _uuid()
    # with goal tolerances SUCCEEDED means the arm is there, not only that the trajectory ended
    # (the servos lag it by a few hundredths of a second)
    at_cube = _goal([(1.5, ABOVE_CUBE), (2.5, AT_CUBE)])  # down from above: the cube stays put
    at_cube["goal_tolerance"] = [{"name": n, "position": 0.002, "velocity": 0.01} for n in ARM]
    at_cube["goal_time_tolerance"] = {"sec": 3, "nanosec": 0}
    ur_peer.call(arm, FJT, "send_goal", {"goal_id": {"uuid": down}, "goal": at_cube})
    result = ur_peer.call(arm, FJT, "get_result", {"goal_id": {"uuid": down}})
    assert result["status"] == SUCCEEDED, result

    def close(position: float) -> dict[str, Any]:
        goal_id = _uuid()
        goal = {"command": {"position": position, "max_effort": 100.0}}
        assert ur_peer.call(
            action, GRIPPER, "send_goal", {"goal_id": {"uuid": goal_id}, "goal": goal}
        )["accepted"]
        return ur_peer.call(
            action, GRIPPER, "get_result", {"goal_id": {"uuid": goal_id}}, timeout=30
        )

    feedback = f"{action}/_action/feedback"
    ur_peer.ask(op="all", topic=feedback, type=f"{GRIPPER}_FeedbackMessage")
    closed = close(0.7)
    moving = ur_peer.ask(op="all", topic=feedback, type=f"{GRIPPER}_FeedbackMessage")
    positions = [m["feedback"]["position"] for m in moving]
    assert len(positions) >= 3 and positions[0] < positions[-1]  # closing, fed back at 20 Hz
    assert abs(positions[-1] - closed["result"]["position"]) < 0.01
    assert closed["status"] == SUCCEEDED
    assert closed["result"]["stalled"] is True and closed["result"]["reached_goal"] is False
    assert 0.40 < closed["result"]["position"] < 0.50  # stopped by the 5 cm cube (0.449 rad)
    opened = close(0.0)
    assert opened["status"] == SUCCEEDED
    assert opened["result"]["reached_goal"] is True and opened["result"]["stalled"] is False
    bad = {"command": {"position": float("nan"), "max_effort": 1.0}}
    assert not ur_peer.call(
        action, GRIPPER, "send_goal", {"goal_id": {"uuid": _uuid()}, "goal": bad}
    )["accepted"]


def test_a_gripper_goal_during_an_arm_goal_leaves_the_arm_goal_running(
    ur_server: Server, ur_peer: UrPeer
) -> None:
    """Separate controllers, as on a UR with a Robotiq: both goals on world 1 succeed."""
    httpx.post(f"{ur_server.url}/v1/worlds/1/reset").raise_for_status()
    gripper = "/world_1/robotiq_gripper_controller/gripper_cmd"
    wanted = [0.3, -1.3, 1.6, -1.8, -1.4, 0.4]
    arm_id, grip_id = _uuid(), _uuid()
    goal = _goal([(2.0, wanted)])
    assert ur_peer.call(SCALED, FJT, "send_goal", {"goal_id": _id(arm_id), "goal": goal})[
        "accepted"
    ]
    wait_for(lambda: _state(ur_server, 1)["target"][0] > 0.01, "the arm goal to move world 1")
    close = {"command": {"position": 0.3, "max_effort": 10.0}}
    assert ur_peer.call(gripper, GRIPPER, "send_goal", {"goal_id": _id(grip_id), "goal": close})[
        "accepted"
    ]
    grip = ur_peer.call(gripper, GRIPPER, "get_result", {"goal_id": _id(grip_id)}, timeout=30)
    assert grip["status"] == SUCCEEDED and grip["result"]["reached_goal"] is True, grip
    result = ur_peer.call(SCALED, FJT, "get_result", {"goal_id": _id(arm_id)}, timeout=30)
    assert result["status"] == SUCCEEDED, result
    target = _state(ur_server, 1)["target"]
    np.testing.assert_allclose(target, [*wanted, 0.3], atol=1e-9)
