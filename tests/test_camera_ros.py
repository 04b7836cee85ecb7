"""Cameras on the ROS 2 graph: sensor_msgs/Image + CameraInfo, judged by rosbags (the bytes)
and by a real rclpy node of the ROS 2 judge (Fast DDS) subscribing to a real server."""

from __future__ import annotations

import json
import math
import random
import subprocess
from pathlib import Path

import httpx
import pytest

from clients.testing import serve
from service.core.cameras import CameraSpec
from service.core.robot import load_robot
from service.surfaces.ros import msgs, msgs_camera
from service.surfaces.ros.camera_dds import camera_info
from tests import ros2_types
from tests.conftest import wait_for

JUDGE = Path("/tmp/ros2-judge")
MJM = load_robot().mjm
FOVY = float(MJM.cam_fovy[MJM.camera("wrist").id])


def _k(width: int, height: int) -> list[float]:
    f = height / 2 / math.tan(math.radians(FOVY) / 2)
    return [f, 0, (width - 1) / 2, 0, f, (height - 1) / 2, 0, 0, 1]


def test_image_and_camera_info_bytes_are_what_rosbags_reads() -> None:
    spec = CameraSpec("wrist", 1, 4, 2, FOVY, True, True, False)
    stamp = msgs.Time(sec=3, nanosec=5)
    image = msgs_camera.Image(
        header=msgs.Header(stamp=stamp, frame_id="wrist_optical_frame"),
        height=2,
        width=4,
        encoding="rgb8",
        is_bigendian=0,
        step=12,
        data=bytes(range(24)),
    )
    got = ros2_types.TYPESTORE.deserialize_cdr(image.serialize(), "sensor_msgs/msg/Image")
    assert (got.height, got.width, got.encoding, got.step) == (2, 4, "rgb8", 12)
    assert bytes(got.data) == bytes(range(24)) and got.header.stamp.nanosec == 5
    info = camera_info(spec, "wrist_optical_frame", stamp, msgs, msgs_camera)
    got = ros2_types.TYPESTORE.deserialize_cdr(info.serialize(), "sensor_msgs/msg/CameraInfo")
    assert list(got.k) == pytest.approx(_k(4, 2)) and got.distortion_model == "plumb_bob"
    assert list(got.p)[:3] == pytest.approx(_k(4, 2)[:3]) and got.roi.width == 0


@pytest.mark.skipif(not (JUDGE / "env.sh").exists(), reason="the ROS 2 judge is not built")
def test_an_rclpy_node_receives_the_wrist_camera(tmp_path: Path) -> None:
    domain = random.SystemRandom().randrange(1, 233)
    extra = ("--ros2", "--ros2-worlds", "1", "--ros2-cameras", "wrist", "--cameras", "wrist=64x48")
    env = {"ROS_DOMAIN_ID": str(domain)}
    with serve(worlds=2, extra_args=extra, env=env, log_dir=tmp_path) as s:
        wait_for(lambda: httpx.get(f"{s.url}/v1/cameras").json()["ready"], "cameras", 300)
        ros = httpx.get(f"{s.url}/v1/ros").json()
        assert ros["dds"]["topics"]["/world_1/wrist/image_raw"] == "sensor_msgs/msg/Image"
        peer = Path(__file__).with_name("rclpy_camera_peer.py")
        cmd = (
            f"source {JUDGE}/env.sh && ROS_DOMAIN_ID={domain} {JUDGE}/venv/bin/python {peer} "
            "/world_1/wrist/image_raw /world_1/wrist/camera_info 60"
        )
        done = subprocess.run(
            ["bash", "-c", cmd], capture_output=True, text=True, timeout=120, cwd=tmp_path
        )
    assert done.returncode == 0, done.stderr[-2000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert set(got) == {"image", "info"}, (got, done.stderr[-2000:])
    image, info = got["image"], got["info"]
    assert (image["width"], image["height"], image["encoding"]) == (64, 48, "rgb8")
    assert image["step"] == 64 * 3 and image["bytes"] == 64 * 48 * 3
    assert image["frame_id"] == "world_1/wrist_optical_frame" == info["frame_id"]
    assert image["red_share"] > 0.005  # the cube between the fingers
    assert info["k"] == pytest.approx(_k(64, 48)) and info["d"] == [0.0] * 5
