"""DDS declarations of the UR driver's actions: FollowJointTrajectory and GripperCommand.

Written from the .msg / .action definitions (trajectory_msgs JointTrajectory and
MultiDOFJointTrajectory with their points; geometry_msgs Twist; control_msgs JointTolerance,
JointComponentTolerance, GripperCommand and the two actions, humble branch;
unique_identifier_msgs UUID; action_msgs GoalInfo, GoalStatus, GoalStatusArray, CancelGoal)
and ROS 2's action design: an action `A` is the services `A_SendGoal` and `A_GetResult`, the
topic `A_FeedbackMessage`, plus action_msgs' CancelGoal service and GoalStatusArray topic.

Service requests and replies travel the way rmw_cyclonedds_cpp sends them: the client's 64-bit
guid and the request's sequence number come first in the CDR stream (its
`cdds_request_header_t`), so each request/response struct here starts with those two fields.
tests/test_ros_actions.py checks the layouts against rosbags. No postponed annotations:
cyclonedds reads the field types at class creation.
"""

import types
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import (
    array,
    float64,
    int8,
    int32,
    int64,
    sequence,
    uint8,
    uint16,
    uint32,
    uint64,
)

from service.surfaces.ros.msgs import Header, Time
from service.surfaces.ros.msgs_tf import Transform, Vector3


@dataclass
class Duration(IdlStruct, typename="builtin_interfaces::msg::dds_::Duration_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class UUID(IdlStruct, typename="unique_identifier_msgs::msg::dds_::UUID_"):
    """A goal's id: 16 random bytes chosen by the client."""

    uuid: array[uint8, 16] = field(default_factory=lambda: [0] * 16)


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class JointTrajectoryPoint(IdlStruct, typename="trajectory_msgs::msg::dds_::JointTrajectoryPoint_"):
    positions: sequence[float64] = field(default_factory=list)
    velocities: sequence[float64] = field(default_factory=list)
    accelerations: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)
    time_from_start: Duration = field(default_factory=Duration)


@dataclass
class JointTrajectory(IdlStruct, typename="trajectory_msgs::msg::dds_::JointTrajectory_"):
    header: Header = field(default_factory=Header)
    joint_names: sequence[str] = field(default_factory=list)
    points: sequence[JointTrajectoryPoint] = field(default_factory=list)


@dataclass
class MultiDOFJointTrajectoryPoint(
    IdlStruct, typename="trajectory_msgs::msg::dds_::MultiDOFJointTrajectoryPoint_"
):
    transforms: sequence[Transform] = field(default_factory=list)
    velocities: sequence[Twist] = field(default_factory=list)
    accelerations: sequence[Twist] = field(default_factory=list)
    time_from_start: Duration = field(default_factory=Duration)


@dataclass
class MultiDOFJointTrajectory(
    IdlStruct, typename="trajectory_msgs::msg::dds_::MultiDOFJointTrajectory_"
):
    header: Header = field(default_factory=Header)
    joint_names: sequence[str] = field(default_factory=list)
    points: sequence[MultiDOFJointTrajectoryPoint] = field(default_factory=list)


@dataclass
class JointTolerance(IdlStruct, typename="control_msgs::msg::dds_::JointTolerance_"):
    name: str = ""
    position: float64 = 0.0
    velocity: float64 = 0.0
    acceleration: float64 = 0.0


@dataclass
class JointComponentTolerance(
    IdlStruct, typename="control_msgs::msg::dds_::JointComponentTolerance_"
):
    joint_name: str = ""
    component: uint16 = 0
    position: float64 = 0.0
    velocity: float64 = 0.0
    acceleration: float64 = 0.0


@dataclass
class FollowJointTrajectoryGoal(
    IdlStruct, typename="control_msgs::action::dds_::FollowJointTrajectory_Goal_"
):
    trajectory: JointTrajectory = field(default_factory=JointTrajectory)
    multi_dof_trajectory: MultiDOFJointTrajectory = field(default_factory=MultiDOFJointTrajectory)
    path_tolerance: sequence[JointTolerance] = field(default_factory=list)
    component_path_tolerance: sequence[JointComponentTolerance] = field(default_factory=list)
    goal_tolerance: sequence[JointTolerance] = field(default_factory=list)
    component_goal_tolerance: sequence[JointComponentTolerance] = field(default_factory=list)
    goal_time_tolerance: Duration = field(default_factory=Duration)


@dataclass
class FollowJointTrajectoryResult(
    IdlStruct, typename="control_msgs::action::dds_::FollowJointTrajectory_Result_"
):
    error_code: int32 = 0
    error_string: str = ""


@dataclass
class FollowJointTrajectoryFeedback(
    IdlStruct, typename="control_msgs::action::dds_::FollowJointTrajectory_Feedback_"
):
    header: Header = field(default_factory=Header)
    joint_names: sequence[str] = field(default_factory=list)
    desired: JointTrajectoryPoint = field(default_factory=JointTrajectoryPoint)
    actual: JointTrajectoryPoint = field(default_factory=JointTrajectoryPoint)
    error: JointTrajectoryPoint = field(default_factory=JointTrajectoryPoint)
    multi_dof_joint_names: sequence[str] = field(default_factory=list)
    multi_dof_desired: MultiDOFJointTrajectoryPoint = field(
        default_factory=MultiDOFJointTrajectoryPoint
    )
    multi_dof_actual: MultiDOFJointTrajectoryPoint = field(
        default_factory=MultiDOFJointTrajectoryPoint
    )
    multi_dof_error: MultiDOFJointTrajectoryPoint = field(
        default_factory=MultiDOFJointTrajectoryPoint
    )


@dataclass
class GripperCommand(IdlStruct, typename="control_msgs::msg::dds_::GripperCommand_"):
    position: float64 = 0.0
    max_effort: float64 = 0.0


@dataclass
class GripperCommandGoal(IdlStruct, typename="control_msgs::action::dds_::GripperCommand_Goal_"):
    command: GripperCommand = field(default_factory=GripperCommand)


@dataclass
class GripperCommandResult(
    IdlStruct, typename="control_msgs::action::dds_::GripperCommand_Result_"
):
    position: float64 = 0.0
    effort: float64 = 0.0
    stalled: bool = False
    reached_goal: bool = False


@dataclass
class GripperCommandFeedback(
    IdlStruct, typename="control_msgs::action::dds_::GripperCommand_Feedback_"
):
    position: float64 = 0.0
    effort: float64 = 0.0
    stalled: bool = False
    reached_goal: bool = False


# -- action_msgs ---------------------------------------------------------------------------------


@dataclass
class GoalInfo(IdlStruct, typename="action_msgs::msg::dds_::GoalInfo_"):
    goal_id: UUID = field(default_factory=UUID)
    stamp: Time = field(default_factory=Time)


@dataclass
class GoalStatus(IdlStruct, typename="action_msgs::msg::dds_::GoalStatus_"):
    goal_info: GoalInfo = field(default_factory=GoalInfo)
    status: int8 = 0


@dataclass
class GoalStatusArray(IdlStruct, typename="action_msgs::msg::dds_::GoalStatusArray_"):
    status_list: sequence[GoalStatus] = field(default_factory=list)


@dataclass
class CancelGoalRequest(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Request_"):
    client_guid: uint64 = 0
    sequence_number: int64 = 0
    goal_info: GoalInfo = field(default_factory=GoalInfo)


@dataclass
class CancelGoalResponse(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Response_"):
    client_guid: uint64 = 0
    sequence_number: int64 = 0
    return_code: int8 = 0
    goals_canceling: sequence[GoalInfo] = field(default_factory=list)


# -- the per-action service and feedback types ---------------------------------------------------


class ActionTypes(NamedTuple):
    """The wire types of one action (`A_SendGoal`, `A_GetResult`, `A_FeedbackMessage`)."""

    send_goal_request: type
    send_goal_response: type
    get_result_request: type
    get_result_response: type
    feedback_message: type
    feedback: type
    result: type


def _struct(typename: str, fields_: dict[str, Any], defaults: dict[str, Any]) -> type:
    """A dataclass IdlStruct built from field annotations (the shapes rosidl generates)."""

    def body(ns: dict[str, Any]) -> None:
        ns["__annotations__"] = fields_
        for name in fields_:
            default = defaults.get(name, 0)
            ns[name] = field(default_factory=default) if callable(default) else default

    name = typename.rsplit("::", 1)[1].strip("_")
    return dataclass(types.new_class(name, (IdlStruct,), {"typename": typename}, body))


def _action(name: str, goal: type, result: type, feedback: type) -> ActionTypes:
    base = f"control_msgs::action::dds_::{name}"
    header = {"client_guid": uint64, "sequence_number": int64}
    ids = {"goal_id": UUID}
    made = {"goal_id": UUID, "goal": goal, "result": result, "feedback": feedback, "stamp": Time}
    return ActionTypes(
        _struct(f"{base}_SendGoal_Request_", {**header, **ids, "goal": goal}, made),
        _struct(f"{base}_SendGoal_Response_", {**header, "accepted": bool, "stamp": Time}, made),
        _struct(f"{base}_GetResult_Request_", {**header, **ids}, made),
        _struct(f"{base}_GetResult_Response_", {**header, "status": int8, "result": result}, made),
        _struct(f"{base}_FeedbackMessage_", {**ids, "feedback": feedback}, made),
        feedback,
        result,
    )


FOLLOW_JOINT_TRAJECTORY = _action(
    "FollowJointTrajectory",
    FollowJointTrajectoryGoal,
    FollowJointTrajectoryResult,
    FollowJointTrajectoryFeedback,
)
GRIPPER_COMMAND = _action(
    "GripperCommand", GripperCommandGoal, GripperCommandResult, GripperCommandFeedback
)
