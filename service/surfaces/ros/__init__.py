"""ROS 2: the armfleet_ros node (packaging/armfleet-ros) as a supervised child on the user's ROS
(`node_process`, `node_env`) and what it reads of the model (`description`: `urdf`, `tf_frames`);
rosbridge (`rosbridge` the protocol, `rosbridge_surface` its socket and `/v1/ros`, `rosapi`,
`rosbridge_actions` on `goals` / `goal_msgs`) with its topic names and JointState rules
(`topics`). Imports as its parent package (surfaces)."""
