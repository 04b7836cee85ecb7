"""Clients for the armfleet service: a library (sync and async), Tk and terminal controllers,
and a live watcher.

    from clients import ArmfleetClient
    with ArmfleetClient("http://127.0.0.1:8000") as arm:
        ack = arm.increment(0, "elbow_joint", 0.1)

Layout: `errors` (exceptions), `models` (typed replies), `calls` (each REST call as a `Call`:
path, body, reply parsing, without I/O; `ArmfleetClient.call` runs any of them), `stream` (socket
URLs, frames, commands, drops and reconnects, without I/O), `client` and `async_client` (the I/O
twins), `trajectory` and `cell` (more calls), `wire` (the binary messages' magics and layouts,
shared with the service), `ros_rules` (the ROS rulebook, shared by rosbridge and the ROS node).
These library modules also install alone, on Python 3.10+ and without the service
(packaging/armfleet-client ships this folder, without its sub-packages), so they import nothing
of `service` and keep to 3.10's language and standard library.

May import: the standard library, httpx, websockets, numpy, orjson; never `service`.

Sub-packages, imported on demand: `clients.apps` (the Tk and terminal controllers, `watch`) and
`clients.testing` (a real server for your own tests; `armfleet_server` fixture for pytest).
"""

import importlib
from typing import TYPE_CHECKING, Any

# What `from clients import X` gives, by the module that defines it. Imported on first use
# (PEP 562), so that the service, which imports `clients.wire`, `clients.models` and
# `clients.ros_rules` (and so this package), does not import httpx, websockets and the I/O
# clients with them: ~0.2 CPU-s of every server and shard worker start.
_HOME = {
    **dict.fromkeys(("AsyncArmfleetClient", "AsyncWorldSession"), "async_client"),
    **dict.fromkeys(("ArmfleetClient", "WorldSession"), "client"),
    "EntityStates": "entity_states",
    **dict.fromkeys(
        (
            "ArmfleetError",
            "CommandRejected",
            "Conflict",
            "Forbidden",
            "InvalidRequest",
            "NotFound",
            "NotReady",
            "PayloadTooLarge",
            "Unauthorized",
            "Unreachable",
        ),
        "errors",
    ),
    **dict.fromkeys(
        (
            "BatchAck",
            "BatchStates",
            "CommandAck",
            "ConnectionStatus",
            "Info",
            "JointInfo",
            "Lease",
            "ResetResult",
            "SafetyAck",
            "SimStatus",
            "WorldState",
        ),
        "models",
    ),
    "Backoff": "stream",
    **dict.fromkeys(
        ("TrajectoriesStarted", "TrajectoryStarted", "TrajectoryStatus", "point", "tolerance"),
        "trajectory",
    ),
}

__all__ = sorted(_HOME)


def __getattr__(name: str) -> Any:
    """`clients.X` for a name of `__all__`: imported from its module on first use."""
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'clients' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"clients.{home}"), name)
    globals()[name] = value  # next time a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


if TYPE_CHECKING:  # what type checkers and editors see: the names, from their modules
    from clients.async_client import AsyncArmfleetClient as AsyncArmfleetClient
    from clients.async_client import AsyncWorldSession as AsyncWorldSession
    from clients.client import ArmfleetClient as ArmfleetClient
    from clients.client import WorldSession as WorldSession
    from clients.entity_states import EntityStates as EntityStates
    from clients.errors import ArmfleetError as ArmfleetError
    from clients.errors import CommandRejected as CommandRejected
    from clients.errors import Conflict as Conflict
    from clients.errors import Forbidden as Forbidden
    from clients.errors import InvalidRequest as InvalidRequest
    from clients.errors import NotFound as NotFound
    from clients.errors import NotReady as NotReady
    from clients.errors import PayloadTooLarge as PayloadTooLarge
    from clients.errors import Unauthorized as Unauthorized
    from clients.errors import Unreachable as Unreachable
    from clients.models import BatchAck as BatchAck
    from clients.models import BatchStates as BatchStates
    from clients.models import CommandAck as CommandAck
    from clients.models import ConnectionStatus as ConnectionStatus
    from clients.models import Info as Info
    from clients.models import JointInfo as JointInfo
    from clients.models import Lease as Lease
    from clients.models import ResetResult as ResetResult
    from clients.models import SafetyAck as SafetyAck
    from clients.models import SimStatus as SimStatus
    from clients.models import WorldState as WorldState
    from clients.stream import Backoff as Backoff
    from clients.trajectory import TrajectoriesStarted as TrajectoriesStarted
    from clients.trajectory import TrajectoryStarted as TrajectoryStarted
    from clients.trajectory import TrajectoryStatus as TrajectoryStatus
    from clients.trajectory import point as point
    from clients.trajectory import tolerance as tolerance
