"""What the judge nodes share: the robot's joint names (as any UR10e + 2F-140 user writes
them), one JSON line out, and spinning until a condition holds."""

from __future__ import annotations

import json
import time

import rclpy
import ur_joints  # beside this file, as `common` is beside the judges
from rclpy.node import Node

JOINTS = [*ur_joints.ARM, ur_joints.GRIPPER]
ARM = JOINTS[:6]


def out(**kw) -> None:
    print(json.dumps(kw), flush=True)


def spin_until(node: Node, pred, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.02)
        if pred():
            return True
    return False


def acked(*pubs, timeout: float = 60.0) -> None:
    """Stay until every subscriber acknowledged what `pubs` sent (a judge that exits sooner
    can take unsent messages with it on a busy box)."""
    from rclpy.duration import Duration

    for pub in pubs:
        pub.wait_for_all_acked(Duration(seconds=timeout))
