"""The plug-in point for surfaces: what a surface may use of a running service, and its shape.

A surface is a way in or out of the service besides the HTTP API (the ROS 2 node's supervisor,
rosbridge, Foxglove; persistence, snapshots and recordings, gets the same context). It is
built before the engine from its own settings model and the `ServiceFacts` (where the service
listens, how many worlds, access, the camera rate: what every surface may know of the service
at build), started once the loop runs and stopped before the loop stops, and it gets a
`SurfaceContext`: the loop (listen with `add_sink`), `Control` (the one door for commands),
the stream hub, the access settings, the client slots it must hold a seat in per client, and
the metrics. Nothing else: no surface sees the runtime, the service's whole settings, the
engine choice or another surface. `armfleet replay` builds the same context for the recorder
that writes a replayed run.

A surface that serves HTTP or WebSocket routes also has a `router` (`Routed`); the app
includes it. Which surfaces exist, and from which settings, is surfaces/registry.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from service.core.access.policy import ClientSlots
from service.core.access.settings import AccessSettings
from service.core.cameras.feed import CameraFeed
from service.core.commands.control import Control
from service.core.metrics import Metrics
from service.core.sim.loop import SimLoop
from service.core.streams.hub import StreamHub


@dataclass(frozen=True)
class ServiceFacts:
    """What every surface builder may know of the service besides its own settings: named
    here rather than the whole settings, so that a surface depends on the few values it uses."""

    host: str  # the service's bind address (surfaces with a port of their own bind there too)
    port: int  # the service's HTTP port (the ROS 2 node calls it)
    worlds: int  # the number of worlds (world lists are checked against it)
    access: AccessSettings  # tokens, leases and command rates: one policy for every surface
    camera_rate: float = 10.0  # images a second per camera on the surfaces that show them

    @property
    def url(self) -> str:
        """The service's HTTP address as a client on this machine reaches it."""
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::", "") else self.host
        return f"http://{host}:{self.port}"


@dataclass(frozen=True, eq=False)  # eq=False: hashed by identity (one per service)
class SurfaceContext:
    """What a surface may use, nothing more (see the module docstring)."""

    loop: SimLoop
    control: Control
    hub: StreamHub | None  # None where nothing streams to sockets (`armfleet replay`)
    access: AccessSettings  # the one access policy's settings (every surface applies it)
    slots: ClientSlots
    metrics: Metrics
    cameras: CameraFeed | None = None  # pictures on request (None: `armfleet replay`)


@runtime_checkable
class Surface(Protocol):
    """An optional way in or out of the service, started with the loop and stopped before it."""

    name: str

    def start(self, ctx: SurfaceContext) -> None:
        """Hook into the loop and control; may block briefly (it runs off the event loop)."""
        ...

    def stop(self) -> None:
        """Unhook and release what it holds; called once, also when `start` never ran."""
        ...


@runtime_checkable
class Routed(Protocol):
    """A surface that also serves routes on the service's port (e.g. rosbridge)."""

    router: Any  # a fastapi.APIRouter, included by the app at creation


@runtime_checkable
class Finishing(Protocol):
    """A surface that writes files: after `stop`, what it could not finish (the exit status)."""

    def unfinished(self) -> list[str]: ...


@runtime_checkable
class Watched(Protocol):
    """A surface with a part that can be down while the service runs (the ROS 2 node's
    supervised child): what is wrong now, for /readyz and the status frames."""

    def problems(self) -> list[str]: ...
