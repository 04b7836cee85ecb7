"""Camera images on the ROS graph: sensor_msgs/Image (rgb8) and CameraInfo, as a camera driver.

For each camera of the node's `cameras` parameter (`armfleet serve --ros2-cameras wrist,...`),
every namespace gets `<ns>/<camera>/image_raw` and `<ns>/<camera>/camera_info` when it opens
(namespaces.py), frame `[world_N/]<camera>_optical_frame`, stamped with the simulated time of
the tick the image shows.
CameraInfo is `plumb_bob` with no distortion, K as `GET /v1/cameras` gives it, P = [K | 0].

The pixels come from armfleet's camera stream (`WS /v1/ws/cameras`, raw RGB, newest only) at
the `camera_rate` parameter, for the worlds whose topics somebody subscribes to (checked with
the node's refresh, twice a second); nobody subscribed, no socket, nothing drawn. One thread
per camera holds that socket and reopens it when the set of listened worlds changes.
"""

from __future__ import annotations

import array
import logging
import threading
from typing import Any
from urllib.parse import urlencode

from sensor_msgs.msg import CameraInfo, Image
from websockets.sync.client import connect

from armfleet_ros import auth
from armfleet_ros.parts import QUIET_PUB
from clients import ros_rules, stream
from clients.calls import Call
from clients.wire import unpack_images as unpack

log = logging.getLogger("armfleet_ros")

QOS_DEPTH = 2  # images are big: a slow subscriber gets the newest, not a backlog


def camera_info(spec: dict, frame: str) -> CameraInfo:
    k = [float(v) for v in spec["K"]]
    info = CameraInfo()
    info.header.frame_id = frame
    info.height, info.width = int(spec["height"]), int(spec["width"])
    info.distortion_model = "plumb_bob"
    info.d = [0.0] * 5
    info.k = k
    info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    info.p = [k[0], 0.0, k[2], 0.0, 0.0, k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0]
    return info


class CameraTopics:
    """One camera's publishers in every namespace and the thread that feeds them."""

    def __init__(self, owner: Any, spec: dict, rate: float) -> None:
        self.owner, self.spec, self.rate = owner, spec, rate
        self.name = str(spec["name"])
        # world -> [(image publisher, info publisher, frame id)] (world 0 may have two names),
        # of the open namespaces (`add`); replaced, never changed, as the refresh reads it
        self.pubs: dict[int, list[tuple[Any, Any, str]]] = {}
        self.listened: tuple[int, ...] = ()
        self.published = 0
        self._changed = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"armfleet-camera-{self.name}")
        self._thread.daemon = True
        self._thread.start()

    def add(self, node: Any, ns: str, world: int) -> None:
        """This camera's topics in a namespace being opened (node.py)."""
        image = node.create_publisher(Image, f"{ns}/{self.name}/image_raw", QOS_DEPTH, **QUIET_PUB)
        info = node.create_publisher(
            CameraInfo, f"{ns}/{self.name}/camera_info", QOS_DEPTH, **QUIET_PUB
        )
        frame = f"{ns.lstrip('/') + '/' if ns else ''}{self.name}_optical_frame"
        self.pubs = {**self.pubs, world: [*self.pubs.get(world, []), (image, info, frame)]}

    def refresh(self) -> None:
        """Which worlds' image or info topics somebody subscribes to now."""
        listened = tuple(
            w
            for w, pubs in sorted(self.pubs.items())
            if any(i.get_subscription_count() or c.get_subscription_count() for i, c, _ in pubs)
        )
        if listened != self.listened:
            self.listened = listened
            self._changed.set()

    def stop(self) -> None:
        self._stop.set()
        self._changed.set()
        self._thread.join(timeout=5)

    def _url(self, worlds: tuple[int, ...]) -> str:
        base = stream.ws_url(self.owner.url, None).replace("/v1/ws", "/v1/ws/cameras", 1)
        query = {
            "camera": self.name,
            "worlds": ",".join(str(w) for w in worlds),
            "rate": f"{self.rate:g}",
            "image": "rgb",
            "format": "raw",
        }
        return f"{base}?{urlencode(query)}"

    def _run(self) -> None:
        backoff = stream.Backoff(maximum=2.0)
        while not self._stop.is_set():
            self._changed.clear()
            worlds = self.listened
            if not worlds:
                self._changed.wait()
                continue
            try:
                with connect(
                    self._url(worlds),
                    max_size=stream.MAX_SIZE,
                    proxy=None,
                    open_timeout=10,
                    additional_headers=auth.headers(),
                ) as ws:
                    while not self._changed.is_set():
                        try:
                            data = ws.recv(timeout=0.5)
                        except TimeoutError:
                            continue
                        if isinstance(data, bytes):
                            self._publish(*unpack(data))
                            backoff.reset()
                    continue
            except stream.LOST as exc:
                log.debug("camera %s: %s", self.name, stream.reason_for(exc))
            except Exception:
                log.exception("camera %s: the stream failed", self.name)
            self._changed.wait(backoff.next())

    def _publish(self, header: dict, images: list[bytes]) -> None:
        sec, nanosec = ros_rules.stamp(int(header["tick"]) * self.owner.tick_dt)
        width, height = int(header["width"]), int(header["height"])
        for world, data in zip(header["worlds"], images, strict=True):
            for image_pub, info_pub, frame in self.pubs.get(int(world), ()):
                msg = Image()
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
                msg.header.frame_id = frame
                msg.height, msg.width, msg.encoding = height, width, "rgb8"
                msg.is_bigendian, msg.step = 0, 3 * width
                msg.data = array.array("B", data)
                info = camera_info(self.spec, frame)
                info.header.stamp = msg.header.stamp
                image_pub.publish(msg)
                info_pub.publish(info)
                self.published += 1


def camera_topics(owner: Any, names: list[str], rate: float) -> list[CameraTopics]:
    """The asked cameras armfleet serves (an unknown name is logged and left out)."""
    if not names:
        return []
    specs = owner.http.call(Call("GET", "/v1/cameras", lambda d: d["cameras"]))
    by_name = {str(s["name"]): s for s in specs}
    out = []
    for name in names:
        if name not in by_name:
            have = ", ".join(by_name) or "none"
            owner.node.get_logger().error(f"cameras: armfleet has no camera {name!r} ({have})")
            continue
        out.append(CameraTopics(owner, by_name[name], rate))
    return out
