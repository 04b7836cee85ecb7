"""The ROS 2 message types armfleet speaks, declared for Cyclone DDS.

Written from the .msg definitions (builtin_interfaces/Time, std_msgs/Header,
sensor_msgs/JointState, rosgraph_msgs/Clock) with the DDS type names ROS 2's middleware uses
(`pkg::msg::dds_::Type_`), so a ROS 2 node sees them as its own types. Samples are serialised as
plain CDR (XCDR1, what ROS 2 Humble sends); tests/test_ros2.py checks the bytes against rosbags'
independent Humble definitions in both directions.

No `from __future__ import annotations` here: cyclonedds reads the field annotations at class
creation and needs them as real types, not strings.
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, sequence, uint32


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
