"""DDS declarations of the UR driver's plain topics: `/robot_description`, `/tf`, `/tf_static`
and `forward_position_controller/commands`.

Written from the .msg definitions (std_msgs String, MultiArrayDimension, MultiArrayLayout,
Float64MultiArray; geometry_msgs Vector3, Quaternion, Transform, TransformStamped;
tf2_msgs TFMessage) with the rmw DDS type names; tests/test_ros_ur.py checks their bytes
against rosbags' Humble typestore. Like service/surfaces/ros/msgs.py, no postponed annotations:
cyclonedds reads the field types at class creation.
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, sequence, uint32

from service.surfaces.ros.msgs import Header


@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    """One text (here: the URDF)."""

    data: str = ""


@dataclass
class MultiArrayDimension(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayDimension_"):
    """Label, size and stride of one array dimension (informative for us)."""

    label: str = ""
    size: uint32 = 0
    stride: uint32 = 0


@dataclass
class MultiArrayLayout(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayLayout_"):
    """How `data` is laid out; forward_position_controller reads `data` only."""

    dim: sequence[MultiArrayDimension] = field(default_factory=list)
    data_offset: uint32 = 0


@dataclass
class Float64MultiArray(IdlStruct, typename="std_msgs::msg::dds_::Float64MultiArray_"):
    """forward_position_controller's command: one position per controller joint [rad]."""

    layout: MultiArrayLayout = field(default_factory=MultiArrayLayout)
    data: sequence[float64] = field(default_factory=list)


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    """Orientation as x y z w (ROS order; MuJoCo's is w x y z)."""

    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    """The child frame's pose in `header.frame_id` at `header.stamp`."""

    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    """What `/tf` and `/tf_static` carry."""

    transforms: sequence[TransformStamped] = field(default_factory=list)
