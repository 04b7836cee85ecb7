"""Camera images as Foxglove topics: foxglove.CompressedImage + foxglove.CameraCalibration.

For each chosen world `w` and camera `c`, into a Foxglove SDK context (the live server's, or a
camera recording's MCAP writer):

- `/world_<w>/<c>/image/compressed`: the RGB image as JPEG, frame `w<w>/<c>_optical`;
- `/world_<w>/<c>/camera_info`: its calibration (K from fovy and size, no distortion, P = K|0).

Both are stamped with the simulated time of the tick the image shows. A thread of its own asks
the camera feed for one picture of all chosen worlds per camera at `rate` Hz, and only for the
cameras whose topics someone listens to (a viewer subscribed, or a recording): nobody looking
costs nothing. Drawing happens on the feed's thread, never on the loop's.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence

import foxglove
from foxglove.channels import CameraCalibrationChannel, CompressedImageChannel
from foxglove.messages import CameraCalibration, CompressedImage, Timestamp

from service.core.cameras.catalog import CameraSpec
from service.core.cameras.feed import CameraFeed
from service.core.cameras.wire import encode
from service.core.errors import ArmfleetError

log = logging.getLogger("armfleet.cameras")


def calibration(spec: CameraSpec, frame_id: str, stamp: Timestamp) -> CameraCalibration:
    k = spec.K
    return CameraCalibration(
        timestamp=stamp,
        frame_id=frame_id,
        width=spec.width,
        height=spec.height,
        distortion_model="plumb_bob",
        D=[0.0] * 5,
        K=k,
        R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P=[k[0], 0.0, k[2], 0.0, 0.0, k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0],
    )


class CameraTopics:
    """Publishes the chosen worlds' cameras into `context` at `rate` Hz while listened to."""

    def __init__(
        self,
        context: foxglove.Context,
        feed: CameraFeed,
        worlds: Sequence[int],
        cameras: Sequence[str],
        rate: float,
        control_hz: float,
        quality: int = 85,
    ) -> None:
        self.context = context  # kept alive: channels and sinks go with it
        self.feed = feed
        self.worlds = list(worlds)
        self.specs = [feed.spec(c) for c in cameras]  # NotFound names an unknown camera
        for spec in self.specs:
            feed.want(spec.name, "rgb")  # Conflict when it does not draw colour
        self._period = 1.0 / rate
        self._hz = control_hz
        self._quality = quality
        self._images = {
            (s.name, w): CompressedImageChannel(
                f"/world_{w}/{s.name}/image/compressed", context=context
            )
            for s in self.specs
            for w in self.worlds
        }
        self._info = {
            (s.name, w): CameraCalibrationChannel(
                f"/world_{w}/{s.name}/camera_info", context=context
            )
            for s in self.specs
            for w in self.worlds
        }
        self.published = 0  # images logged
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self._run, name="armfleet-camera-topics", daemon=True
        )

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=30)

    def _run(self) -> None:
        due = time.monotonic()
        while not self._stop.is_set():
            for spec in self.specs:
                try:
                    self._publish(spec)
                except ArmfleetError as exc:  # cameras still warming up: try next period
                    log.debug("camera topics: %s", exc)
                except Exception:
                    log.exception("camera topics: %s failed", spec.name)
            due = max(due + self._period, time.monotonic())
            self._stop.wait(max(0.0, due - time.monotonic()))

    def _publish(self, spec: CameraSpec) -> None:
        worlds = [
            w
            for w in self.worlds
            if self._images[spec.name, w].has_sinks() or self._info[spec.name, w].has_sinks()
        ]
        if not worlds:
            return
        shot = self.feed.shoot(worlds, spec.name).result(timeout=60)
        ns = round(shot.tick * 1e9 / self._hz)
        stamp = Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)
        for i, w in enumerate(worlds):
            frame = f"w{w}/{spec.name}_optical"
            jpeg = encode(shot.rgb[i], "rgb", "jpeg", self._quality)
            image = CompressedImage(timestamp=stamp, frame_id=frame, data=jpeg, format="jpeg")
            self._images[spec.name, w].log(image, log_time=ns)
            self._info[spec.name, w].log(calibration(spec, frame, stamp), log_time=ns)
            self.published += 1
