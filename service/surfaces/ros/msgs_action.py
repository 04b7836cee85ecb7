"""DDS declarations of the UR driver's actions: FollowJointTrajectory and GripperCommand.

The .msg / .action fields (trajectory_msgs JointTrajectory and
MultiDOFJointTrajectory with their points; geometry_msgs Twist; control_msgs JointTolerance,
JointComponentTolerance, GripperCommand and the two actions, humble branch;
unique_identifier_msgs UUID; action_msgs GoalInfo, GoalStatus, GoalStatusArray, CancelGoal)
and ROS 2's action design: an action `A` is the services `A_SendGoal` and `A_GetResult`, the
topic `A_FeedbackMessage`, plus action_msgs' CancelGoal service and GoalStatusArray topic.

Service requests and replies travel the way rmw_cyclonedds_cpp sends them: the client's 64-bit
guid and the request's sequence number come first in the CDR stream (its
`cdds_request_header_t`), so each request/response struct here starts with those two fields
(`REQUEST_HEADER`). The types are made by service/surfaces/ros/idl.py;
tests/test_ros_actions.py checks the layouts against rosbags.
"""

from typing import NamedTuple

from service.surfaces.ros.idl import REQUEST_HEADER, message

# declared there, named below (and still importable from here, as before)
from service.surfaces.ros.msgs import Header, Time  # noqa: F401
from service.surfaces.ros.msgs_tf import Transform, Vector3  # noqa: F401

Duration = message("builtin_interfaces/msg/Duration", "int32 sec\nuint32 nanosec")

# A goal's id: 16 random bytes chosen by the client.
UUID = message("unique_identifier_msgs/msg/UUID", "uint8[16] uuid")

Twist = message("geometry_msgs/msg/Twist", "Vector3 linear\nVector3 angular")

JointTrajectoryPoint = message(
    "trajectory_msgs/msg/JointTrajectoryPoint",
    """
    float64[] positions
    float64[] velocities
    float64[] accelerations
    float64[] effort
    builtin_interfaces/Duration time_from_start
    """,
)
JointTrajectory = message(
    "trajectory_msgs/msg/JointTrajectory",
    "std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points",
)
MultiDOFJointTrajectoryPoint = message(
    "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint",
    """
    geometry_msgs/Transform[] transforms
    geometry_msgs/Twist[] velocities
    geometry_msgs/Twist[] accelerations
    builtin_interfaces/Duration time_from_start
    """,
)
MultiDOFJointTrajectory = message(
    "trajectory_msgs/msg/MultiDOFJointTrajectory",
    "std_msgs/Header header\nstring[] joint_names\nMultiDOFJointTrajectoryPoint[] points",
)

JointTolerance = message(
    "control_msgs/msg/JointTolerance",
    "string name\nfloat64 position\nfloat64 velocity\nfloat64 acceleration",
)
JointComponentTolerance = message(
    "control_msgs/msg/JointComponentTolerance",
    """
    string joint_name
    uint16 component
    float64 position
    float64 velocity
    float64 acceleration
    """,
)

FollowJointTrajectoryGoal = message(
    "control_msgs/action/FollowJointTrajectory_Goal",
    """
    trajectory_msgs/JointTrajectory trajectory
    trajectory_msgs/MultiDOFJointTrajectory multi_dof_trajectory
    control_msgs/JointTolerance[] path_tolerance
    control_msgs/JointComponentTolerance[] component_path_tolerance
    control_msgs/JointTolerance[] goal_tolerance
    control_msgs/JointComponentTolerance[] component_goal_tolerance
    builtin_interfaces/Duration goal_time_tolerance
    """,
)
FollowJointTrajectoryResult = message(
    "control_msgs/action/FollowJointTrajectory_Result", "int32 error_code\nstring error_string"
)
FollowJointTrajectoryFeedback = message(
    "control_msgs/action/FollowJointTrajectory_Feedback",
    """
    std_msgs/Header header
    string[] joint_names
    trajectory_msgs/JointTrajectoryPoint desired
    trajectory_msgs/JointTrajectoryPoint actual
    trajectory_msgs/JointTrajectoryPoint error
    string[] multi_dof_joint_names
    trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired
    trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual
    trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error
    """,
)

GripperCommand = message("control_msgs/msg/GripperCommand", "float64 position\nfloat64 max_effort")
GripperCommandGoal = message(
    "control_msgs/action/GripperCommand_Goal", "control_msgs/GripperCommand command"
)
# control_msgs gives the result and the feedback the same four fields
_GRIPPER_STATE = "float64 position\nfloat64 effort\nbool stalled\nbool reached_goal"
GripperCommandResult = message("control_msgs/action/GripperCommand_Result", _GRIPPER_STATE)
GripperCommandFeedback = message("control_msgs/action/GripperCommand_Feedback", _GRIPPER_STATE)

# -- action_msgs ---------------------------------------------------------------------------------

GoalInfo = message(
    "action_msgs/msg/GoalInfo",
    "unique_identifier_msgs/UUID goal_id\nbuiltin_interfaces/Time stamp",
)
GoalStatus = message("action_msgs/msg/GoalStatus", "GoalInfo goal_info\nint8 status")
GoalStatusArray = message("action_msgs/msg/GoalStatusArray", "GoalStatus[] status_list")
CancelGoalRequest = message(
    "action_msgs/srv/CancelGoal_Request", REQUEST_HEADER + "action_msgs/GoalInfo goal_info"
)
CancelGoalResponse = message(
    "action_msgs/srv/CancelGoal_Response",
    REQUEST_HEADER + "int8 return_code\naction_msgs/GoalInfo[] goals_canceling",
)


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


def _action(name: str, goal: type, result: type, feedback: type) -> ActionTypes:
    """ROS 2's action design: the services and the feedback message around goal/result/feedback."""
    a = f"control_msgs/action/{name}"
    goal_id = "unique_identifier_msgs/UUID goal_id\n"
    return ActionTypes(
        message(f"{a}_SendGoal_Request", f"{REQUEST_HEADER}{goal_id}{a}_Goal goal"),
        message(
            f"{a}_SendGoal_Response",
            f"{REQUEST_HEADER}bool accepted\nbuiltin_interfaces/Time stamp",
        ),
        message(f"{a}_GetResult_Request", REQUEST_HEADER + goal_id),
        message(f"{a}_GetResult_Response", f"{REQUEST_HEADER}int8 status\n{a}_Result result"),
        message(f"{a}_FeedbackMessage", f"{goal_id}{a}_Feedback feedback"),
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
