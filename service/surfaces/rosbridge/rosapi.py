"""rosapi's services on the rosbridge socket: what topics and actions there are, time, version.

Each service takes the client's session and the call's `args` and returns the response's
`values` (a ProtocolError becomes `result: false`). `typedefs_full_text` follows rosapi's
layout: the root type's fields, then each dependency under `MSG: name`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from clients import ros_rules
from service.surfaces.rosbridge import actions as rosbridge_actions
from service.surfaces.rosbridge import topics
from service.surfaces.rosbridge.base import topic_name
from service.surfaces.rosbridge.goal_msgs import action_names
from service.surfaces.rosbridge.topics import (
    CLOCK_TYPE,
    JOINT_STATE_TYPE,
    SAFETY_MODE_TYPE,
    STRING,
    TF,
)

_RULE = "=" * 80

# Field lists of the message definitions (ros2/common_interfaces, rcl_interfaces), in the
# `typedefs_full_text` layout rosapi uses: root type, then each dependency under `MSG: name`.
_TIME_DEF = "int32 sec\nuint32 nanosec\n"
_HEADER_DEF = "builtin_interfaces/Time stamp\nstring frame_id\n"
TYPEDEFS = {
    JOINT_STATE_TYPE: (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        f"float64[] effort\n\n{_RULE}\nMSG: std_msgs/Header\n{_HEADER_DEF}\n{_RULE}\n"
        f"MSG: builtin_interfaces/Time\n{_TIME_DEF}"
    ),
    CLOCK_TYPE: (
        f"builtin_interfaces/Time clock\n\n{_RULE}\nMSG: builtin_interfaces/Time\n{_TIME_DEF}"
    ),
    STRING: "string data\n",
    SAFETY_MODE_TYPE: "uint8 data\n",
    TF: (
        f"geometry_msgs/TransformStamped[] transforms\n\n{_RULE}\n"
        "MSG: geometry_msgs/TransformStamped\n"
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n\n"
        f"{_RULE}\nMSG: std_msgs/Header\n{_HEADER_DEF}\n{_RULE}\n"
        f"MSG: builtin_interfaces/Time\n{_TIME_DEF}\n{_RULE}\nMSG: geometry_msgs/Transform\n"
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n\n"
        f"{_RULE}\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n\n"
        f"{_RULE}\nMSG: geometry_msgs/Quaternion\n"
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
    ),
}


def topics_(session: Any, args: Any) -> dict[str, Any]:
    table = session.server.topic_map.all_topics()
    return {"topics": list(table), "types": list(table.values())}


def topics_and_raw_types(session: Any, args: Any) -> dict[str, Any]:
    table = session.server.topic_map.all_topics()
    return {
        "topics": list(table),
        "types": list(table.values()),
        "typedefs_full_text": [TYPEDEFS[t] for t in table.values()],
    }


def topic_type(session: Any, args: Any) -> dict[str, Any]:
    topic = args[0] if isinstance(args, list) and args else args.get("topic")
    name = topic_name(topic, "args.topic")
    return {"type": session.server.topic_map.all_topics().get(name, "")}


def get_time(session: Any, args: Any) -> dict[str, Any]:
    sec, nanosec = ros_rules.stamp(topics.sim_seconds(session.loop.latest, session.tick_dt))
    return {"time": {"sec": sec, "nanosec": nanosec}}


def get_ros_version(session: Any, args: Any) -> dict[str, Any]:
    return {"version": 2, "distro": "humble"}


def action_servers(session: Any, args: Any) -> dict[str, Any]:
    """rosapi/GetActionServers: every action armfleet serves (the UR driver's, per world)."""
    return {"action_servers": sorted(action_names(session.server.topic_map.namespaces()))}


SERVICES: dict[str, Callable[[Any, Any], dict[str, Any]]] = {
    "/rosapi/topics": topics_,
    "/rosapi/topics_and_raw_types": topics_and_raw_types,
    "/rosapi/topic_type": topic_type,
    "/rosapi/get_time": get_time,
    "/rosapi/get_ros_version": get_ros_version,
    "/rosapi/action_servers": action_servers,
}


def find(name: str) -> Callable[[Any, Any], dict[str, Any]] | None:
    """The service called `name`: rosapi's, or an action's cancel_goal (cancel all)."""
    if name.endswith(CANCEL_SUFFIX):
        action = name.removesuffix(CANCEL_SUFFIX)
        return lambda session, args: rosbridge_actions.cancel_all(session, action)
    return SERVICES.get(name)


CANCEL_SUFFIX = "/_action/cancel_goal"
