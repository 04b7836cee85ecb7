"""DDS declarations of the UR driver's plain topics: `/robot_description`, `/tf`, `/tf_static`
and `forward_position_controller/commands`.

The .msg fields of std_msgs String, MultiArrayDimension, MultiArrayLayout, Float64MultiArray;
geometry_msgs Vector3, Quaternion, Transform, TransformStamped; tf2_msgs TFMessage, made into
DDS types by service/surfaces/ros/idl.py; tests/test_ros_ur.py checks their bytes against
rosbags' Humble typestore.
"""

from service.surfaces.ros.idl import message

# declared there, named below (and still importable from here, as before)
from service.surfaces.ros.msgs import Header  # noqa: F401

# One text (here: the URDF).
String = message("std_msgs/msg/String", "string data")

# Label, size and stride of one array dimension (informative for us).
MultiArrayDimension = message(
    "std_msgs/msg/MultiArrayDimension", "string label\nuint32 size\nuint32 stride"
)

# How `data` is laid out; forward_position_controller reads `data` only.
MultiArrayLayout = message(
    "std_msgs/msg/MultiArrayLayout", "MultiArrayDimension[] dim\nuint32 data_offset"
)

# forward_position_controller's command: one position per controller joint [rad].
Float64MultiArray = message(
    "std_msgs/msg/Float64MultiArray", "MultiArrayLayout layout\nfloat64[] data"
)

Vector3 = message("geometry_msgs/msg/Vector3", "float64 x\nfloat64 y\nfloat64 z")

# Orientation as x y z w (ROS order; MuJoCo's is w x y z); the identity by default.
Quaternion = message(
    "geometry_msgs/msg/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1"
)

Transform = message("geometry_msgs/msg/Transform", "Vector3 translation\nQuaternion rotation")

# The child frame's pose in `header.frame_id` at `header.stamp`.
TransformStamped = message(
    "geometry_msgs/msg/TransformStamped",
    "std_msgs/Header header\nstring child_frame_id\nTransform transform",
)

# What `/tf` and `/tf_static` carry.
TFMessage = message("tf2_msgs/msg/TFMessage", "geometry_msgs/TransformStamped[] transforms")
