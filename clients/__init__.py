"""Clients for the armfleet service: a library (sync and async), Tk and terminal controllers,
and a live watcher.

    from clients import ArmfleetClient
    with ArmfleetClient("http://127.0.0.1:8000") as arm:
        ack = arm.increment(0, "elbow_joint", 0.1)

The UIs (`clients.tk_controller`, `clients.tui`, `clients.watch`) are imported on demand, as
is `clients.testing` (a real server for your own tests; `armfleet_server` fixture for pytest).

Layout: `errors` (exceptions), `models` (typed replies), `_http` and `_stream` (requests, frames
and reconnects, without I/O), `client` and `async_client` (the I/O twins). Those library modules
also install alone, on Python 3.10+ and without the service (packaging/armfleet-client), so they
import nothing of `service` and keep to 3.10's language and standard library.
"""

from clients._stream import Backoff
from clients.async_client import AsyncArmfleetClient, AsyncWorldSession
from clients.client import ArmfleetClient, WorldSession
from clients.entity_states import EntityStates
from clients.errors import (
    ArmfleetError,
    CommandRejected,
    Conflict,
    Forbidden,
    InvalidRequest,
    NotFound,
    NotReady,
    PayloadTooLarge,
    Unauthorized,
    Unreachable,
)
from clients.models import (
    BatchAck,
    BatchStates,
    CommandAck,
    ConnectionStatus,
    Info,
    JointInfo,
    Lease,
    ResetResult,
    SimStatus,
    WorldState,
)
from clients.trajectory import (
    TrajectoriesStarted,
    TrajectoryStarted,
    TrajectoryStatus,
    point,
    tolerance,
)

__all__ = [
    "ArmfleetClient",
    "ArmfleetError",
    "AsyncArmfleetClient",
    "AsyncWorldSession",
    "Backoff",
    "BatchAck",
    "BatchStates",
    "CommandAck",
    "CommandRejected",
    "Conflict",
    "ConnectionStatus",
    "EntityStates",
    "Forbidden",
    "Info",
    "InvalidRequest",
    "JointInfo",
    "Lease",
    "NotFound",
    "NotReady",
    "PayloadTooLarge",
    "ResetResult",
    "SimStatus",
    "TrajectoriesStarted",
    "TrajectoryStarted",
    "TrajectoryStatus",
    "Unauthorized",
    "Unreachable",
    "WorldSession",
    "WorldState",
    "point",
    "tolerance",
]
