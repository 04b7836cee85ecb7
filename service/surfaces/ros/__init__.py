"""ROS 2 (`--ros2`): the armfleet_ros node (packaging/armfleet-ros) as a supervised child on the
user's ROS (`node_process`, `node_env`), and the robot as ROS sees it, which the node reads over
HTTP and rosbridge publishes (`description`: `urdf`, `tf_frames`).

rosbridge, the other ROS face, is service/surfaces/rosbridge/; what a message or goal means is
the ROS rulebook both faces import (clients/ros_rules.py). Imports as its parent package
(surfaces).
"""
