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
    SafetyAck,
    SimStatus,
    WorldState,
)
from clients.stream import Backoff
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
    "SafetyAck",
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
