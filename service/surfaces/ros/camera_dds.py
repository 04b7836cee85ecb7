"""Camera images on the ROS 2 graph: sensor_msgs/Image + sensor_msgs/CameraInfo over DDS.

For each camera of `--ros2-cameras`: world 0 publishes `/<camera>/image_raw` and
`/<camera>/camera_info`, every `--ros2-worlds` world N `/world_N/<camera>/...`, as a ROS 2
camera driver does (`rgb8`, frame `<camera>_optical_frame` with the world's prefix, stamped with
the simulated time of the tick the image shows; CameraInfo with `plumb_bob`, zero distortion,
K from fovy and size, P = [K | 0]). A thread of its own draws, at `--camera-rate`, only the
worlds whose topics have a subscriber (checked every half second): nobody subscribed, nothing
drawn. RViz's Image and Camera displays and `ros2 topic echo` read them.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from service.core.cameras import CameraSpec
from service.core.errors import ArmfleetError
from service.surfaces.ros import topics
from service.surfaces.ros.qos import rclpy_default as _qos
from service.surfaces.ros.topics import TopicMap

if TYPE_CHECKING:
    from service.core.camera_feed import CameraFeed
    from service.core.surface import SurfaceContext

log = logging.getLogger("armfleet.ros2")
_MATCH_CHECK_S = 0.5


def camera_topics(topic_map: TopicMap, camera: str) -> dict[str, int]:
    """Image topic → world for one camera (its camera_info topic is beside it)."""
    return {f"{ns}/{camera}/image_raw": w for ns, w in topic_map.namespaces().items()}


def camera_info(spec: CameraSpec, frame_id: str, stamp: Any, msgs: Any, cam: Any) -> Any:
    k = spec.K
    return cam.CameraInfo(
        header=msgs.Header(stamp=stamp, frame_id=frame_id),
        height=spec.height,
        width=spec.width,
        distortion_model="plumb_bob",
        d=[0.0] * 5,
        k=k,
        r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p=[k[0], 0.0, k[2], 0.0, 0.0, k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0],
    )


class RosCameras:
    """The camera writers on an existing DDS participant and the thread that feeds them."""

    def __init__(
        self,
        dp: Any,
        ctx: SurfaceContext,
        topic_map: TopicMap,
        cameras: Sequence[str],
        rate: float,
    ) -> None:
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        from service.surfaces.ros import msgs, msgs_camera

        assert ctx.cameras is not None
        self.feed: CameraFeed = ctx.cameras
        self._msgs, self._cam = msgs, msgs_camera
        self._tick_dt = ctx.loop.batch.tick_dt
        self._period = 1.0 / rate
        self.specs = [self.feed.spec(c) for c in cameras]
        for spec in self.specs:
            self.feed.want(spec.name, "rgb")
        self._entities: list[Any] = []
        # (camera, world) -> (image writer, info writer, frame id)
        self.writers: dict[tuple[str, int], tuple[Any, Any, str]] = {}
        self.topic_types: dict[str, str] = {}  # for GET /v1/ros
        for spec in self.specs:
            for image_topic, world in camera_topics(topic_map, spec.name).items():
                info_topic = image_topic.rsplit("/", 1)[0] + "/camera_info"
                pair = []
                for name, kind in (
                    (image_topic, msgs_camera.Image),
                    (info_topic, msgs_camera.CameraInfo),
                ):
                    t = Topic(dp, topics.dds_name(name), kind)
                    w = DataWriter(dp, t, qos=_qos(1))
                    self._entities += [t, w]
                    pair.append(w)
                self.topic_types[image_topic] = "sensor_msgs/msg/Image"
                self.topic_types[info_topic] = "sensor_msgs/msg/CameraInfo"
                prefix = image_topic.rsplit("/", 2)[0].lstrip("/")
                frame = f"{prefix + '/' if prefix else ''}{spec.name}_optical_frame"
                self.writers[spec.name, world] = (pair[0], pair[1], frame)
        self.published = 0
        self._listened: dict[str, list[int]] = {}
        self._checked = -1e9
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="armfleet-ros2-cameras", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=30)
        for entity in reversed(self._entities):
            entity.__del__()
        self._entities.clear()

    def _listening(self) -> dict[str, list[int]]:
        now = time.monotonic()
        if now - self._checked >= _MATCH_CHECK_S:
            self._checked = now
            self._listened = {
                spec.name: [
                    w
                    for (name, w), (img, info, _) in self.writers.items()
                    if name == spec.name
                    and (
                        img.get_publication_matched_status().current_count
                        or info.get_publication_matched_status().current_count
                    )
                ]
                for spec in self.specs
            }
        return self._listened

    def _run(self) -> None:
        due = time.monotonic()
        while not self._stop.is_set():
            for spec in self.specs:
                worlds = self._listening().get(spec.name, [])
                if not worlds:
                    continue
                try:
                    self._publish(spec, worlds)
                except ArmfleetError as exc:  # warming up: the next period tries again
                    log.debug("ROS 2 cameras: %s", exc)
                except Exception:
                    log.exception("ROS 2 cameras: %s failed", spec.name)
            due = max(due + self._period, time.monotonic())
            self._stop.wait(max(0.0, due - time.monotonic()))

    def _publish(self, spec: CameraSpec, worlds: list[int]) -> None:
        shot = self.feed.shoot(worlds, spec.name).result(timeout=60)
        sec, nanosec = topics.stamp(shot.tick * self._tick_dt)
        stamp = self._msgs.Time(sec=sec, nanosec=nanosec)
        for i, world in enumerate(worlds):
            image_writer, info_writer, frame = self.writers[spec.name, world]
            header = self._msgs.Header(stamp=stamp, frame_id=frame)
            image_writer.write(
                self._cam.Image(
                    header=header,
                    height=spec.height,
                    width=spec.width,
                    encoding="rgb8",
                    is_bigendian=0,
                    step=3 * spec.width,
                    data=shot.rgb[i].tobytes(),
                )
            )
            info_writer.write(camera_info(spec, frame, stamp, self._msgs, self._cam))
            self.published += 1
