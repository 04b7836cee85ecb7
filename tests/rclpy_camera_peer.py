"""An rclpy node (run by the ROS 2 judge's Python, /tmp/ros2-judge) that subscribes to one
camera's image and camera_info topics and prints what it got as one JSON line; for
tests/test_camera_ros.py. Arguments: image topic, info topic, seconds to wait."""

import json
import sys
import time

import rclpy
from sensor_msgs.msg import CameraInfo, Image

image_topic, info_topic, wait_s = sys.argv[1], sys.argv[2], float(sys.argv[3])
rclpy.init()
node = rclpy.create_node("armfleet_camera_judge")
got = {}


def on_image(msg: Image) -> None:
    data = bytes(msg.data)
    pixels = [data[i : i + 3] for i in range(0, len(data), 3)]
    red = sum(1 for r, g, b in pixels if r > 60 and r > 1.8 * g and r > 1.8 * b)
    got.setdefault(
        "image",
        {
            "height": msg.height,
            "width": msg.width,
            "encoding": msg.encoding,
            "step": msg.step,
            "bytes": len(data),
            "frame_id": msg.header.frame_id,
            "stamp": [msg.header.stamp.sec, msg.header.stamp.nanosec],
            "red_share": red / max(1, len(pixels)),
        },
    )


def on_info(msg: CameraInfo) -> None:
    got.setdefault(
        "info",
        {
            "height": msg.height,
            "width": msg.width,
            "k": list(msg.k),
            "p": list(msg.p),
            "d": list(msg.d),
            "distortion_model": msg.distortion_model,
            "frame_id": msg.header.frame_id,
        },
    )


node.create_subscription(Image, image_topic, on_image, 10)
node.create_subscription(CameraInfo, info_topic, on_info, 10)
deadline = time.monotonic() + wait_s
while time.monotonic() < deadline and len(got) < 2:
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps(got), flush=True)
node.destroy_node()
rclpy.shutdown()
