"""Which surfaces a service has, and the settings that ask for each: the one list to extend.

Adding a surface is one module (a class with `name`, `start(ctx)` and `stop()`, see
core/surface.py), its settings model beside it (each field an `ARMFLEET_*` variable and an
`armfleet serve` option once it is a section of service/settings.py's `Settings`), and one
`Entry` in `REGISTRY` below: (name, module, settings model, build). A builder gets its own
settings and the `ServiceFacts` (core/surface.py: where the service listens, the worlds,
access, the camera rate), never the whole settings, and imports its module only when its
settings ask for it, so an unused surface costs nothing (no ROS 2 node, no Foxglove SDK).
The registry builds them in order, each builder seeing the surfaces built before it
(rosbridge reports the ROS 2 node's process); the runtime starts them in that order once the
loop runs and stops them in reverse.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from pydantic import BaseModel

from service.core.surface import Routed, ServiceFacts, Surface, SurfaceContext
from service.surfaces.foxglove.settings import CameraRecordSettings, FoxgloveSettings
from service.surfaces.ros.settings import Ros2Settings
from service.surfaces.ur.settings import UrSettings

log = logging.getLogger("armfleet")
M = TypeVar("M", bound=BaseModel)


class Sections(Protocol):
    """The service's settings as the registry reads them (service/settings.py's `Settings`,
    which ranks above surfaces: so the registry names what it uses, not that class)."""

    def section(self, model: type[M]) -> M: ...

    def facts(self) -> ServiceFacts: ...


# build(its settings, the facts, the surfaces built before it) -> the surface, or None where
# its settings do not ask for it
Build = Callable[[Any, ServiceFacts, Mapping[str, Surface]], Surface | None]


@dataclass(frozen=True)
class Entry:
    """One surface: its `name`, the module that holds its class (the builder imports it only
    when the settings ask for the surface; `build_surfaces` checks that it did), the settings
    model it is built from, and how."""

    name: str
    module: str
    settings: type[BaseModel]
    build: Build


def _foxglove(
    own: FoxgloveSettings, facts: ServiceFacts, built: Mapping[str, Surface]
) -> Surface | None:
    if not own.enabled:
        return None
    from service.surfaces.foxglove.live import FoxgloveLive

    # A client presents its token (the administrator's or a lease's) as a parameter.
    return FoxgloveLive(
        facts.host,
        own.port,
        own.worlds,
        own.rate,
        cameras=(own.cameras, facts.camera_rate),
        access=facts.access,
    )


def _camera_recording(
    own: CameraRecordSettings, facts: ServiceFacts, built: Mapping[str, Surface]
) -> Surface | None:
    if own.path is None:
        return None
    from service.surfaces.foxglove.camera_recording import CameraRecording

    return CameraRecording(own.path, own.worlds, own.cameras, facts.camera_rate)


def _ros2(own: Ros2Settings, facts: ServiceFacts, built: Mapping[str, Surface]) -> Surface | None:
    if not own.enabled:
        return None
    from service.surfaces.ros.node_process import RosNode

    return RosNode(own, facts)  # ValueError (one line) where no ROS 2 is found


def _rosbridge(own: Ros2Settings, facts: ServiceFacts, built: Mapping[str, Surface]) -> Surface:
    from service.surfaces.rosbridge.surface import RosbridgeSurface

    return RosbridgeSurface(own, facts, built.get("ros2"))  # always on; reports the ROS 2 node


def _ur(own: UrSettings, facts: ServiceFacts, built: Mapping[str, Surface]) -> Surface | None:
    if not own.enabled:
        return None
    from service.surfaces.ur.surface import UrSurface

    return UrSurface(own, facts)  # ValueError naming ur_worlds / ur_addresses


# In start order. The names are the surfaces' `name`s.
REGISTRY: tuple[Entry, ...] = (
    Entry("foxglove", "service.surfaces.foxglove.live", FoxgloveSettings, _foxglove),
    Entry(
        "camera_recording",
        "service.surfaces.foxglove.camera_recording",
        CameraRecordSettings,
        _camera_recording,
    ),
    Entry("ros2", "service.surfaces.ros.node_process", Ros2Settings, _ros2),
    Entry("rosbridge", "service.surfaces.rosbridge.surface", Ros2Settings, _rosbridge),
    Entry("ur", "service.surfaces.ur.surface", UrSettings, _ur),
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


def build_surfaces(settings: Sections) -> SurfaceSet:
    """The surfaces the settings ask for (ValueError where their options are invalid)."""
    facts = settings.facts()
    built: dict[str, Surface] = {}
    for entry in REGISTRY:
        surface = entry.build(settings.section(entry.settings), facts, built)
        if surface is not None:
            assert type(surface).__module__ == entry.module, (entry.name, type(surface))
            built[entry.name] = surface
    return SurfaceSet(list(built.values()))
