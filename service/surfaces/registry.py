"""Which surfaces a service has, and the settings that ask for each: the one list to extend.

Adding a surface is one module (a class with `name`, `start(ctx)` and `stop()`, see
core/surface.py) plus one entry in `REGISTRY` below, and its options as fields of
core/settings.py (each an `ARMFLEET_*` variable; an `armfleet serve` option is one `_opt` line
in cli.py). The registry builds them in order, each builder
seeing the surfaces built before it (rosbridge reports the ROS 2 node's process); the runtime
starts them in that order once the loop runs and stops them in reverse. A builder imports its
surface only when the settings ask for it, so an unused surface costs nothing (no ROS 2 node,
no Foxglove SDK).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

from service.core.settings import Settings
from service.core.surface import Routed, Surface, SurfaceContext

log = logging.getLogger("armfleet")

Builder = Callable[[Settings, Mapping[str, Surface]], Surface | None]


def _foxglove(s: Settings, built: Mapping[str, Surface]) -> Surface | None:
    if not s.foxglove:
        return None
    from service.surfaces.foxglove_live import FoxgloveLive

    # A client presents its token (the administrator's or a lease's) as a parameter.
    return FoxgloveLive(
        s.host,
        s.foxglove_port,
        s.foxglove_worlds,
        s.foxglove_rate,
        cameras=(s.foxglove_cameras, s.camera_rate),
        settings=s,
    )


def _camera_recording(s: Settings, built: Mapping[str, Surface]) -> Surface | None:
    if s.camera_record is None:
        return None
    from service.surfaces.camera_recording import CameraRecording

    return CameraRecording(
        s.camera_record, s.camera_record_worlds, s.camera_record_cameras, s.camera_rate
    )


def _ros2(s: Settings, built: Mapping[str, Surface]) -> Surface | None:
    if not s.ros2:
        return None
    from service.surfaces.ros.node_process import RosNode

    return RosNode(s)  # ValueError (one line) where no ROS 2 is found


def _rosbridge(s: Settings, built: Mapping[str, Surface]) -> Surface:
    from service.surfaces.rosbridge.surface import RosbridgeSurface

    return RosbridgeSurface(s, built.get("ros2"))  # always on; reports the ROS 2 node too


# (name, builder), in start order. The names are the surfaces' `name`s.
REGISTRY: tuple[tuple[str, Builder], ...] = (
    ("foxglove", _foxglove),
    ("camera_recording", _camera_recording),
    ("ros2", _ros2),
    ("rosbridge", _rosbridge),
)


class SurfaceSet:
    """The surfaces of one service, in start order."""

    def __init__(self, surfaces: Sequence[Surface]) -> None:
        self._all = tuple(surfaces)

    def __iter__(self) -> Iterator[Surface]:
        return iter(self._all)

    def routers(self) -> list[Any]:
        """The routers of the surfaces that serve routes on the service's port."""
        return [s.router for s in self._all if isinstance(s, Routed)]

    def start(self, ctx: SurfaceContext) -> None:
        for surface in self._all:
            surface.start(ctx)

    def stop(self) -> None:
        """Stop every surface, last started first; one failing does not keep the rest up."""
        for surface in reversed(self._all):
            try:
                surface.stop()
            except Exception:
                log.exception("surface %s failed to stop", surface.name)


def build_surfaces(settings: Settings) -> SurfaceSet:
    """The surfaces the settings ask for (ValueError where their options are invalid)."""
    built: dict[str, Surface] = {}
    for name, build in REGISTRY:
        surface = build(settings, built)
        if surface is not None:
            built[name] = surface
    return SurfaceSet(list(built.values()))
