"""ROS 2: the DDS bridge (`dds`, `ur_dds`, `discovery`, `qos`, `msgs*` declared through `idl`,
`urdf`, `tf_frames`), rosbridge (`rosbridge` the protocol, `rosbridge_surface` its socket and
`/v1/ros`), and the topic names and JointState rules both share (`topics`). Imports as its
parent package (surfaces)."""
