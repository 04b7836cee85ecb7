"""Camera images on the ROS graph through the armfleet_ros node (`--ros2-cameras`), judged by a
real rclpy subscriber (tests/rclpy/camera_judge.py): sensor_msgs/Image in rgb8 whose pixels
are, byte for byte, what `GET /v1/worlds/{w}/cameras/{name}?format=raw` draws at the same
(paused) tick, stamped with that tick's simulated time; CameraInfo whose K is `GET /v1/cameras`'
and P = [K | 0]. Nobody subscribed: nothing is drawn.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import time
from typing import Any

import httpx
import pytest

from tests import ros2_judge
from tests.conftest import serve, wait_for
from tests.test_ros_node import node_report, server_env

pytestmark = pytest.mark.skipif(
    ros2_judge.skip_reason() is not None, reason=str(ros2_judge.skip_reason())
)

GRAPH = 70  # a ROS domain of its own (offset from this process's)
CAMERA_JUDGE = ros2_judge.JUDGE_SCRIPT.parent / "camera_judge.py"


def camera_judge(*prefixes: str, wait_s: float = 60) -> dict[str, Any]:
    done = subprocess.run(
        [ros2_judge.python(), str(CAMERA_JUDGE), str(wait_s), *prefixes],
        env=ros2_judge.on_domain(ros2_judge.env(), GRAPH),
        capture_output=True,
        text=True,
        timeout=wait_s + 60,
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    assert done.returncode == 0 and lines, f"camera judge failed:\n{done.stdout}\n{done.stderr}"
    return json.loads(lines[-1])


def renders(http: httpx.Client) -> float:
    for line in http.get("/metrics").text.splitlines():
        if line.startswith("armfleet_camera_renders_total"):
            return float(line.split()[1])
    raise AssertionError("no armfleet_camera_renders_total in /metrics")


def test_camera_topics_carry_what_the_camera_draws(tmp_path: Any) -> None:
    args = ["--engine", "mujoco", "--ros2", "--ros2-worlds", "1"]
    args += ["--ros2-cameras", "wrist,overview", "--camera-rate", "5"]
    args += ["--ros2-python", ros2_judge.python()]
    with (
        serve(
            worlds=2, mode="paused", extra_args=args, env=server_env(GRAPH), log_dir=tmp_path
        ) as srv,
        httpx.Client(base_url=srv.url, timeout=60) as http,
    ):
        wait_for(lambda: http.get("/v1/cameras").json()["ready"], "the cameras", 300)
        node_report(http)
        http.post("/v1/sim/step", json={"ticks": 3})
        http.put("/v1/worlds/1/targets", json={"name": ["elbow_joint"], "position": [1.0]})
        tick = http.post("/v1/sim/step", json={"ticks": 40}).json()["tick"]
        idle = renders(http)
        time.sleep(1.5)
        assert renders(http) == idle  # nobody subscribed: nothing drawn
        seen = camera_judge("/world_1/wrist", "/overview")
        specs = {c["name"]: c for c in http.get("/v1/cameras").json()["cameras"]}
        info = http.get("/v1/info").json()
        for prefix, world, frame in (
            ("/world_1/wrist", 1, "world_1/wrist_optical_frame"),
            ("/overview", 0, "overview_optical_frame"),
        ):
            name = prefix.rsplit("/", 1)[1]
            spec = specs[name]
            image, cam = seen[prefix]["image"], seen[prefix]["info"]
            assert (image["width"], image["height"]) == (spec["width"], spec["height"])
            assert image["encoding"] == "rgb8" and image["step"] == 3 * spec["width"]
            assert image["bytes"] == 3 * spec["width"] * spec["height"]
            assert image["frame_id"] == cam["frame_id"] == frame
            assert image["stdev"] > 5  # a picture, not a blank
            assert image["stamp"] == pytest.approx(tick / info["control_hz"], abs=1e-6)
            raw = http.get(f"/v1/worlds/{world}/cameras/{name}", params={"format": "raw"})
            assert raw.status_code == 200 and int(raw.headers["X-Armfleet-Tick"]) == tick
            assert image["sha256"] == hashlib.sha256(raw.content).hexdigest()
            k = spec["K"]
            assert cam["k"] == pytest.approx(k) and cam["distortion_model"] == "plumb_bob"
            assert cam["p"] == pytest.approx([k[0], 0, k[2], 0, 0, k[4], k[5], 0, 0, 0, 1, 0])
            assert (cam["width"], cam["height"]) == (spec["width"], spec["height"])

        def counted() -> dict[str, int] | None:
            images = http.get("/v1/ros").json()["node"]["report"]["images"]
            return images if images.get("wrist") and images.get("overview") else None

        wait_for(counted, "the node's count of images published", 30)
