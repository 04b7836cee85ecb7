"""rosbridge: the rosbridge v2 protocol on the service's own port, for ROS web and script
clients (roslibpy, roslib.js), always on.

- `surface`: the surface (its socket at `/` and `/rosbridge`, `GET /v1/ros` for both ROS faces,
  and what the ROS node reads or reports: `/v1/ros/robot_description`, `/v1/ros/frames`,
  `PUT /v1/ros/node`);
- `protocol`: one client's connection (ops, outbox); `base`: what every capability shares;
- `topics`: topic names ↔ worlds and the JointState and clock messages; `frames`: the robot
  topics (tf, tf_static, robot_description); `rosapi`: the rosapi services;
  `sim_entities`: simulation_interfaces' entity services;
- `actions` (the protocol's action ops), `goals` (the goal runner) and `goal_msgs` (goals and
  feedback in their JSON shape).

What a message or goal means (the JointState rule, the action constants, the stall rule, the
result codes, the refusal counter) is the ROS rulebook's, clients/ros_rules.py, which the ROS 2
node (packaging/armfleet-ros) applies too. The robot's description (URDF, tf tree) is
service/surfaces/ros/, beside the node's supervisor. Imports as its parent package (surfaces).
"""
