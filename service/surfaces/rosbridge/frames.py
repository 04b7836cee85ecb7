"""rosbridge's robot topics, per namespace like the joint topics: `robot_description` and
`tf_static` (latched, as transient-local topics are: sent once to each subscriber) and `tf`
(the moving frames at the subscription's rate, from the snapshot's body poses), so that
roslib.js viewers (ros3djs) and Foxglove over rosbridge can draw the arm. The frames and the
URDF are the ones the ROS 2 node publishes (tf_frames.py, urdf.py via description.py).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import orjson

from clients import ros_rules
from service.core.sim.loop import SimLoop
from service.core.sim.types import Snapshot
from service.surfaces.ros import description
from service.surfaces.ros.tf_frames import FrameTree
from service.surfaces.rosbridge import topics

TF_TYPE = "tf2_msgs/msg/TFMessage"
STRING_TYPE = "std_msgs/msg/String"
KINDS = {"tf": TF_TYPE, "tf_static": TF_TYPE, "robot_description": STRING_TYPE}
LATCHED = ("tf_static", "robot_description")


def frame_topic(namespaces: dict[str, int], topic: str) -> tuple[int, str] | None:
    """(world, kind) of a robot topic, or None."""
    ns, _, kind = topic.rpartition("/")
    if kind in KINDS and ns in namespaces:
        return namespaces[ns], kind
    return None


def frame_topics(namespaces: dict[str, int]) -> dict[str, str]:
    """Topic → type of every robot topic (for rosapi's listings)."""
    return {f"{ns}/{kind}": kind_type for ns in namespaces for kind, kind_type in KINDS.items()}


def _transform(parent: str, child: str, pos: Any, quat: Any, stamp: dict) -> dict[str, Any]:
    w, x, y, z = (float(v) for v in quat)
    return {
        "header": {"stamp": stamp, "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": dict(zip("xyz", (float(v) for v in pos), strict=True)),
            "rotation": {"x": x, "y": y, "z": z, "w": w},
        },
    }


class RobotFrames:
    """The tree and the URDF of the served model, rendered as rosbridge publish frames."""

    def __init__(self, loop: SimLoop) -> None:
        mjm = loop.batch.robot.mjm
        self.tree = FrameTree(mjm)
        self.urdf = description.robot_description(mjm, loop.spec)

    def latched(self, topic: str, kind: str) -> bytes:
        if kind == "robot_description":
            msg: dict[str, Any] = {"data": self.urdf}
        else:
            zero = {"sec": 0, "nanosec": 0}
            msg = {
                "transforms": [
                    _transform(t.parent, t.child, t.pos, t.quat, zero) for t in self.tree.static
                ]
            }
        return orjson.dumps({"op": "publish", "topic": topic, "msg": msg})

    def tf(self, topic: str, world: int, tick_dt: float) -> Callable[[Snapshot], bytes]:
        tree = self.tree

        def render(s: Snapshot) -> bytes:
            pos, quat = tree.moving(s.body_pos[world], s.body_quat[world])
            sec, nanosec = ros_rules.stamp(topics.sim_seconds(s, tick_dt))
            stamp = {"sec": sec, "nanosec": nanosec}
            pairs = zip(tree.moving_parents, tree.moving_children, pos, quat, strict=True)
            msg = {"transforms": [_transform(p, c, xyz, q, stamp) for p, c, xyz, q in pairs]}
            return orjson.dumps({"op": "publish", "topic": topic, "msg": msg})

        return render
