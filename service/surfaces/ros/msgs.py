"""The ROS 2 message types armfleet speaks, declared for Cyclone DDS.

Written from the .msg definitions (builtin_interfaces/Time, std_msgs/Header,
sensor_msgs/JointState, rosgraph_msgs/Clock, and rmw_dds_common's graph messages) with the DDS
type names ROS 2's middleware uses (`pkg::msg::dds_::Type_`), so a ROS 2 node sees them as its
own types. Samples are serialised as plain CDR (XCDR1, what ROS 2 Humble sends);
tests/test_ros2.py checks the bytes against rosbags' independent Humble definitions both ways.

No `from __future__ import annotations` here: cyclonedds reads the field annotations at class
creation and needs them as real types, not strings.
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, bounded_str, float64, int32, sequence, uint8, uint32


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    """A point in time: whole seconds plus nanoseconds (0..999,999,999)."""

    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    """Timestamp and coordinate frame of the data that follows."""

    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    """Joint names with position [rad], velocity [rad/s], effort [N·m]; arrays may be empty."""

    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    """The simulated time nodes with `use_sim_time` follow."""

    clock: Time = field(default_factory=Time)


@dataclass
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    """A DDS entity's identity as ROS 2 writes it: the 16-byte GUID, zero-padded to 24."""

    data: array[uint8, 24] = field(default_factory=lambda: [0] * 24)


@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    """One node: its name and the readers and writers that belong to it."""

    node_namespace: bounded_str[256] = "/"
    node_name: bounded_str[256] = ""
    reader_gid_seq: sequence[Gid] = field(default_factory=list)
    writer_gid_seq: sequence[Gid] = field(default_factory=list)


@dataclass
class ParticipantEntitiesInfo(
    IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
):
    """What `ros_discovery_info` carries: a participant's nodes (how `ros2 node list` finds us)."""

    gid: Gid = field(default_factory=Gid)
    node_entities_info_seq: sequence[NodeEntitiesInfo] = field(default_factory=list)
