"""armfleet_ros: armfleet's worlds as a ROS 2 node of the user's own ROS installation.

Runs on the installation's Python (Humble's 3.10 on) with its rclpy and message packages, and
reaches armfleet over HTTP/WebSocket with armfleet's client library (`clients`, the
armfleet-client distribution). Modules: `node` (parameters, wiring, `main`), `world` (one
namespace's topics), `namespaces` (when a namespace's endpoints are made), `actions`
(FollowJointTrajectory, GripperCommand), `frames` (/tf), `link` (the WebSockets), `convert`
(messages checked and turned into commands). What a message or goal means is the ROS
rulebook (`clients.ros_rules`), which rosbridge applies too.

May import: rclpy, the distribution's messages and the client library's public modules (never
`clients._*`, never `service`: only the client library is installed beside the node).
"""
