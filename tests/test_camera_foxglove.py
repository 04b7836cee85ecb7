"""Cameras in Foxglove and in MCAP: a real server, judged by the mcap reader, protobuf decoders
built from the schemas the file or the server carries, and Pillow.

* `--camera-record`: the MCAP file holds foxglove.CompressedImage (JPEG) and
  foxglove.CameraCalibration for the chosen worlds and camera; K matches fovy and size; the
  images decode and show the cube.
* `--foxglove-cameras`: a Foxglove WebSocket viewer that subscribes gets the same two topics.
"""

from __future__ import annotations

import io
import json
import math
import time

import httpx
import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from PIL import Image
from websockets.sync.client import connect

from clients.testing import free_port, serve
from service.core.sim.robot import load_robot
from tests.conftest import wait_for
from tests.test_foxglove import SUBPROTOCOL, FoxgloveClient

MJM = load_robot().mjm
WRIST = MJM.camera("wrist").id


def _decoder(schema_name: str, data: bytes):
    files = descriptor_pb2.FileDescriptorSet.FromString(data)
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def _shows_the_cube(jpeg: bytes) -> bool:
    rgb = np.asarray(Image.open(io.BytesIO(jpeg)).convert("RGB")).astype(int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return bool(((r > 60) & (r > 1.8 * g) & (r > 1.8 * b)).mean() > 0.005)


def _check_k(k: list[float], width: int, height: int) -> None:
    f = height / 2 / math.tan(math.radians(MJM.cam_fovy[WRIST]) / 2)
    assert list(k) == pytest.approx([f, 0, (width - 1) / 2, 0, f, (height - 1) / 2, 0, 0, 1])


def test_camera_recording_is_an_mcap_of_images_and_calibrations(tmp_path) -> None:
    path = tmp_path / "cams.mcap"
    extra = ("--camera-record", str(path), "--camera-record-worlds", "0-1", "--camera-rate", "10")
    with serve(worlds=2, extra_args=extra, log_dir=tmp_path) as s:
        wait_for(
            lambda: httpx.get(f"{s.url}/v1/cameras", timeout=60).json()["ready"], "cameras", 300
        )
        time.sleep(2.0)
    with open(path, "rb") as f:
        reader = make_reader(f)
        messages = list(reader.iter_messages())
    topics: dict[str, list] = {}
    for schema, channel, message in messages:
        topics.setdefault(channel.topic, []).append((schema, channel, message))
    assert set(topics) == {
        f"/world_{w}/wrist/{t}" for w in (0, 1) for t in ("image/compressed", "camera_info")
    }
    schema, channel, _ = topics["/world_0/wrist/image/compressed"][0]
    assert schema.name == "foxglove.CompressedImage" and channel.message_encoding == "protobuf"
    image_cls = _decoder(schema.name, schema.data)
    images = [image_cls.FromString(m.data) for _, _, m in topics["/world_1/wrist/image/compressed"]]
    assert len(images) >= 5  # about 10 a second for 2 s (fewer on a loaded box)
    assert all(i.format == "jpeg" and i.frame_id == "w1/wrist_optical" for i in images)
    assert _shows_the_cube(images[-1].data)
    stamps = [i.timestamp.seconds * 10**9 + i.timestamp.nanos for i in images]
    assert stamps == sorted(stamps) and stamps[-1] > stamps[0]  # simulated time moves on
    schema, _, message = topics["/world_0/wrist/camera_info"][-1]
    info = _decoder(schema.name, schema.data).FromString(message.data)
    assert (info.width, info.height) == (128, 96)
    _check_k(info.K, 128, 96)


def test_foxglove_viewers_get_the_camera_topics(tmp_path) -> None:
    port = free_port()
    extra = ("--foxglove", "--foxglove-port", str(port), "--foxglove-worlds", "0-1")
    extra += ("--foxglove-cameras", "wrist", "--cameras", "wrist=160x120")
    with serve(worlds=2, extra_args=extra, log_dir=tmp_path) as s:
        wait_for(
            lambda: httpx.get(f"{s.url}/v1/cameras", timeout=60).json()["ready"], "cameras", 300
        )
        with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], max_size=None) as ws:
            c = FoxgloveClient(ws)
            c.handshake()
            image_topic, info_topic = (
                "/world_1/wrist/image/compressed",
                "/world_1/wrist/camera_info",
            )
            wait_for(lambda: image_topic in c.channels or c._control(json.loads(ws.recv(5))), "ad")
            c.subscribe([image_topic, info_topic])
            image = c.decoder(image_topic).FromString(c.next_message(image_topic, 30))
            info = c.decoder(info_topic).FromString(c.next_message(info_topic, 30))
    assert image.format == "jpeg" and _shows_the_cube(image.data)
    assert Image.open(io.BytesIO(image.data)).size == (160, 120)
    _check_k(info.K, 160, 120)
