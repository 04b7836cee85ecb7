"""rosbridge's robot topics judged by roslibpy 2.1: `/robot_description` and `/tf_static` for a
late subscriber (once, as transient-local), `/tf` composed as tf2 does equals MuJoCo's body
poses, per namespace; rosapi lists them."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest
import roslibpy

from tests.conftest import Server, serve, wait_for
from tests.test_ros_node import _poses, compose


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    extra = ("--ros2-worlds", "1", "--engine", "mujoco")
    with serve(worlds=2, extra_args=extra, log_dir=tmp_path_factory.mktemp("frames")) as srv:
        yield srv


def _collect(ros: roslibpy.Ros, topic: str, kind: str) -> tuple[list[dict[str, Any]], Any]:
    got: list[dict[str, Any]] = []
    lock = threading.Lock()

    def take(msg: dict[str, Any]) -> None:
        with lock:
            got.append(msg)

    sub = roslibpy.Topic(ros, topic, kind)
    sub.subscribe(take)
    return got, sub


@pytest.mark.parametrize("ns", ["", "/world_1"])
def test_description_and_frames_over_rosbridge(server: Server, ros: roslibpy.Ros, ns: str) -> None:
    urdf = httpx.get(f"{server.url}/v1/ros/robot_description").json()["urdf"]
    desc, d_sub = _collect(ros, f"{ns}/robot_description", "std_msgs/msg/String")
    static, s_sub = _collect(ros, f"{ns}/tf_static", "tf2_msgs/msg/TFMessage")
    moving, m_sub = _collect(ros, f"{ns}/tf", "tf2_msgs/msg/TFMessage")
    try:
        wait_for(lambda: desc and static and len(moving) >= 3, "the robot topics")
        assert desc[0]["data"] == urdf
        edges: dict[str, Any] = {}
        for msg in (static[0], moving[-1]):
            for t in msg["transforms"]:
                tr, q = t["transform"]["translation"], t["transform"]["rotation"]
                edges[t["child_frame_id"]] = (
                    t["header"]["frame_id"],
                    [tr["x"], tr["y"], tr["z"]],
                    [q["w"], q["x"], q["y"], q["z"]],
                )
        assert {"base_link", "tool0", "flange"} <= set(edges)
        frames = httpx.get(f"{server.url}/v1/ros/frames").json()
        poses = _poses(server, 1 if ns else 0)  # nothing commands the arms: they rest
        for m in frames["moving"]:
            pos, _ = compose(edges, m["child"])
            np.testing.assert_allclose(pos, poses[m["child_body"], :3], atol=2e-4)
        wait_for(lambda: len(moving) >= 6, "more /tf")
        assert len(desc) == 1 and len(static) == 1  # latched: once
    finally:
        for sub in (d_sub, s_sub, m_sub):
            sub.unsubscribe()


def test_rosapi_lists_the_robot_topics(ros: roslibpy.Ros) -> None:
    service = roslibpy.Service(ros, "/rosapi/topics", "rosapi/Topics")
    reply = service.call(roslibpy.ServiceRequest({}), timeout=10)
    table = dict(zip(reply["topics"], reply["types"], strict=True))
    assert table["/world_1/tf"] == "tf2_msgs/msg/TFMessage"
    assert table["/robot_description"] == "std_msgs/msg/String"
