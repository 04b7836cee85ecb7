"""`/tf` and `/tf_static` from armfleet's tf tree (`GET /v1/ros/frames`) and body poses.

The fixed transforms come as they are; each moving frame is its child body's world pose seen
from its parent body's (`WS /v1/ws/view` pose frames, float32), which is how tf2 composes them
back into MuJoCo's world poses.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from clients import quat as quaternion


def _transform(parent: str, child: str, pos: Any, quat: Any, sec: int, nanosec: int) -> Any:
    t = TransformStamped()
    t.header.stamp.sec, t.header.stamp.nanosec = sec, nanosec
    t.header.frame_id, t.child_frame_id = parent, child
    tr, rot = t.transform.translation, t.transform.rotation
    tr.x, tr.y, tr.z = (float(v) for v in pos)
    rot.w, rot.x, rot.y, rot.z = (float(v) for v in quat)
    return t


class TfTree:
    """The robot's frames, as armfleet describes them."""

    def __init__(self, desc: dict[str, Any]) -> None:
        self.static = desc["static"]
        moving = desc["moving"]
        self.parents = [m["parent"] for m in moving]
        self.children = [m["child"] for m in moving]
        self._pb = np.array([m["parent_body"] for m in moving], dtype=np.int64)
        self._cb = np.array([m["child_body"] for m in moving], dtype=np.int64)

    def static_message(self) -> Any:
        """Every fixed transform in one message (`/tf_static`, transient local)."""
        msg = TFMessage()
        msg.transforms = [
            _transform(s["parent"], s["child"], s["pos"], s["quat"], 0, 0) for s in self.static
        ]
        return msg

    def moving_message(self, poses: np.ndarray, sec: int, nanosec: int) -> Any:
        """The moving frames of one world from its body poses (nbody, 7: x y z w x y z)."""
        pos = poses[:, :3].astype(np.float64)
        quat = poses[:, 3:].astype(np.float64)
        pp, pq = pos[self._pb], quat[self._pb]
        cp, cq = pos[self._cb], quat[self._cb]
        inv = quaternion.conj(pq)
        rel_q = quaternion.mul(inv, cq)
        rel_q /= np.linalg.norm(rel_q, axis=-1, keepdims=True)
        rel_p = quaternion.rotate(inv, cp - pp)
        msg = TFMessage()
        msg.transforms = [
            _transform(p, c, rel_p[i], rel_q[i], sec, nanosec)
            for i, (p, c) in enumerate(zip(self.parents, self.children, strict=True))
        ]
        return msg
