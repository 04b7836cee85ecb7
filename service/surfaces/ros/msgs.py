"""The ROS 2 message types armfleet speaks, declared for Cyclone DDS.

Their .msg fields (builtin_interfaces/Time, std_msgs/Header, sensor_msgs/JointState,
rosgraph_msgs/Clock, and rmw_dds_common's graph messages), made into DDS types with the names
ROS 2's middleware uses (`pkg::msg::dds_::Type_`) by service/surfaces/ros/idl.py, so a ROS 2
node sees them as its own types. Samples are serialised as plain CDR (XCDR1, what ROS 2 Humble
sends); tests/test_ros2.py checks the bytes against rosbags' independent Humble definitions
both ways.
"""

from service.surfaces.ros.idl import message

# A point in time: whole seconds plus nanoseconds (0..999,999,999).
Time = message("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec")

# Timestamp and coordinate frame of the data that follows.
Header = message("std_msgs/msg/Header", "builtin_interfaces/Time stamp\nstring frame_id")

# Joint names with position [rad], velocity [rad/s], effort [N·m]; arrays may be empty.
JointState = message(
    "sensor_msgs/msg/JointState",
    """
    std_msgs/Header header
    string[] name
    float64[] position
    float64[] velocity
    float64[] effort
    """,
)

# The simulated time nodes with `use_sim_time` follow.
Clock = message("rosgraph_msgs/msg/Clock", "builtin_interfaces/Time clock")

# A DDS entity's identity as ROS 2 writes it: the 16-byte GUID, zero-padded to 24.
Gid = message("rmw_dds_common/msg/Gid", "uint8[24] data")

# One node: its name and the readers and writers that belong to it (namespace "/" unless set).
NodeEntitiesInfo = message(
    "rmw_dds_common/msg/NodeEntitiesInfo",
    """
    string<=256 node_namespace "/"
    string<=256 node_name
    Gid[] reader_gid_seq
    Gid[] writer_gid_seq
    """,
)

# What `ros_discovery_info` carries: a participant's nodes (how `ros2 node list` finds us).
ParticipantEntitiesInfo = message(
    "rmw_dds_common/msg/ParticipantEntitiesInfo",
    "Gid gid\nNodeEntitiesInfo[] node_entities_info_seq",
)
