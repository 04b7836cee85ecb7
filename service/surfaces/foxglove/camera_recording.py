"""Camera recordings: chosen worlds' cameras into an MCAP file, for Foxglove and any MCAP reader.

`armfleet serve --camera-record cams.mcap --camera-record-cameras wrist
--camera-record-worlds 0-3 --camera-rate 10` writes, from the start until the service stops,
`/world_<w>/<camera>/image/compressed` (foxglove.CompressedImage, JPEG) and
`/world_<w>/<camera>/camera_info` (foxglove.CameraCalibration), protobuf-encoded, log time =
simulated time of the tick shown (camera_topics.py). It is a file of its own beside the state
recording (`--record`), written by the Foxglove SDK's MCAP writer, so that images never slow
the state recording's writer.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import foxglove

from service.core.sim.worlds import world_list
from service.core.surface import SurfaceContext
from service.surfaces.foxglove.camera_topics import CameraTopics

log = logging.getLogger("armfleet.cameras")


class CameraRecording:
    """A surface: one MCAP file of camera images while the service runs."""

    name = "camera_recording"

    def __init__(self, path: Path, worlds: str, cameras: str, rate: float) -> None:
        self.path = Path(path).expanduser()
        self._worlds = worlds
        self._cameras = [c.strip() for c in cameras.split(",") if c.strip()]
        self._rate = rate
        self._writer: Any = None
        self._topics: CameraTopics | None = None
        self._problems: list[str] = []

    def start(self, ctx: SurfaceContext) -> None:
        if ctx.cameras is None:
            self._problems.append("camera recording: this service has no cameras")
            return
        worlds = world_list(self._worlds, ctx.loop.batch.nworld, "camera_record_worlds")
        context = foxglove.Context()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._writer = foxglove.open_mcap(self.path, allow_overwrite=True, context=context)
        self._topics = CameraTopics(
            context, ctx.cameras, worlds, self._cameras, self._rate, ctx.loop.batch.control_hz
        )
        self._topics.start()
        log.info("recording cameras %s of worlds %s to %s", self._cameras, worlds, self.path)

    def stop(self) -> None:
        if self._topics is not None:
            self._topics.stop()
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def unfinished(self) -> list[str]:
        """Finishing: what could not be written (the service's exit status)."""
        return list(self._problems)
