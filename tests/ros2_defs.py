"""Message definitions rosbags' Humble typestore lacks, as .msg text (fields only).

From ros-controls/control_msgs (humble branch: msg/JointTolerance.msg,
msg/JointComponentTolerance.msg, msg/GripperCommand.msg, action/FollowJointTrajectory.action,
action/GripperCommand.action) and ros2/rcl_interfaces (action_msgs/srv/CancelGoal.srv). An
action's goal, result and feedback sections become `<Action>_Goal`, `_Result`, `_Feedback`,
and ROS 2's action design wraps them into the send_goal / get_result services and the feedback
message, which are spelled out here the way rosidl generates them.
"""

from __future__ import annotations

_TOLERANCE = "string name\nfloat64 position\nfloat64 velocity\nfloat64 acceleration\n"
_COMPONENT_TOLERANCE = (
    "uint16 X_AXIS=1\nuint16 Y_AXIS=2\nuint16 Z_AXIS=3\nuint16 TRANSLATION=4\nuint16 ROTATION=5\n"
    "string joint_name\nuint16 component\nfloat64 position\nfloat64 velocity\n"
    "float64 acceleration\n"
)
_FJT_GOAL = (
    "trajectory_msgs/JointTrajectory trajectory\n"
    "trajectory_msgs/MultiDOFJointTrajectory multi_dof_trajectory\n"
    "control_msgs/JointTolerance[] path_tolerance\n"
    "control_msgs/JointComponentTolerance[] component_path_tolerance\n"
    "control_msgs/JointTolerance[] goal_tolerance\n"
    "control_msgs/JointComponentTolerance[] component_goal_tolerance\n"
    "builtin_interfaces/Duration goal_time_tolerance\n"
)
_FJT_RESULT = (
    "int32 SUCCESSFUL=0\nint32 INVALID_GOAL=-1\nint32 INVALID_JOINTS=-2\n"
    "int32 OLD_HEADER_TIMESTAMP=-3\nint32 PATH_TOLERANCE_VIOLATED=-4\n"
    "int32 GOAL_TOLERANCE_VIOLATED=-5\nint32 error_code\nstring error_string\n"
)
_FJT_FEEDBACK = (
    "std_msgs/Header header\nstring[] joint_names\n"
    "trajectory_msgs/JointTrajectoryPoint desired\ntrajectory_msgs/JointTrajectoryPoint actual\n"
    "trajectory_msgs/JointTrajectoryPoint error\nstring[] multi_dof_joint_names\n"
    "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired\n"
    "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual\n"
    "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error\n"
)
_GRIPPER_STATE = "float64 position\nfloat64 effort\nbool stalled\nbool reached_goal\n"


def _action(pkg: str, name: str, goal: str, result: str, feedback: str) -> dict[str, str]:
    base = f"{pkg}/action/{name}"
    return {
        f"{base}_Goal": goal,
        f"{base}_Result": result,
        f"{base}_Feedback": feedback,
        f"{base}_SendGoal_Request": (f"unique_identifier_msgs/UUID goal_id\n{base}_Goal goal\n"),
        f"{base}_SendGoal_Response": "bool accepted\nbuiltin_interfaces/Time stamp\n",
        f"{base}_GetResult_Request": "unique_identifier_msgs/UUID goal_id\n",
        f"{base}_GetResult_Response": f"int8 status\n{base}_Result result\n",
        f"{base}_FeedbackMessage": (
            f"unique_identifier_msgs/UUID goal_id\n{base}_Feedback feedback\n"
        ),
    }


DEFINITIONS: dict[str, str] = {
    "control_msgs/msg/JointTolerance": _TOLERANCE,
    "control_msgs/msg/JointComponentTolerance": _COMPONENT_TOLERANCE,
    "control_msgs/msg/GripperCommand": "float64 position\nfloat64 max_effort\n",
    "action_msgs/srv/CancelGoal_Request": "action_msgs/GoalInfo goal_info\n",
    "action_msgs/srv/CancelGoal_Response": (
        "int8 ERROR_NONE=0\nint8 ERROR_REJECTED=1\nint8 ERROR_UNKNOWN_GOAL_ID=2\n"
        "int8 ERROR_GOAL_TERMINATED=3\nint8 return_code\naction_msgs/GoalInfo[] goals_canceling\n"
    ),
    **_action("control_msgs", "FollowJointTrajectory", _FJT_GOAL, _FJT_RESULT, _FJT_FEEDBACK),
    **_action(
        "control_msgs",
        "GripperCommand",
        "control_msgs/GripperCommand command\n",
        _GRIPPER_STATE,
        _GRIPPER_STATE,
    ),
}
