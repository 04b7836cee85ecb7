"""A judge node on a real rclpy: what a camera's topics carry, as RViz's Image display reads
them. Nothing of armfleet is imported: rclpy and sensor_msgs only.

    python camera_judge.py SECONDS PREFIX [PREFIX ...]   # e.g. 60 /world_1/wrist /overview

For each PREFIX it subscribes to PREFIX/image_raw and PREFIX/camera_info and prints one JSON
line: per prefix, the first Image (sizes, encoding, frame, stamp, the pixels' SHA-256, mean and
spread) and the first CameraInfo (K, P, D, model, frame).
"""

from __future__ import annotations

import hashlib
import statistics
import sys

import rclpy
from common import out, spin_until
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image


def image_summary(msg: Image) -> dict:
    data = bytes(msg.data)
    sample = data[::7]
    return {
        "height": msg.height,
        "width": msg.width,
        "encoding": msg.encoding,
        "step": msg.step,
        "bytes": len(data),
        "frame_id": msg.header.frame_id,
        "stamp": msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9,
        "sha256": hashlib.sha256(data).hexdigest(),
        "mean": statistics.fmean(sample),
        "stdev": statistics.pstdev(sample),
    }


def info_summary(msg: CameraInfo) -> dict:
    return {
        "height": msg.height,
        "width": msg.width,
        "k": list(msg.k),
        "p": list(msg.p),
        "d": list(msg.d),
        "distortion_model": msg.distortion_model,
        "frame_id": msg.header.frame_id,
    }


def main(wait_s: float, prefixes: list[str]) -> None:
    rclpy.init()
    node = Node("armfleet_camera_judge")
    got: dict = {p: {} for p in prefixes}
    for p in prefixes:
        node.create_subscription(
            Image, f"{p}/image_raw", lambda m, p=p: got[p].setdefault("image", image_summary(m)), 2
        )
        node.create_subscription(
            CameraInfo,
            f"{p}/camera_info",
            lambda m, p=p: got[p].setdefault("info", info_summary(m)),
            2,
        )
    spin_until(node, lambda: all(len(g) == 2 for g in got.values()), wait_s)
    out(**got)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main(float(sys.argv[1]), sys.argv[2:])
