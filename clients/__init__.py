"""Clients for the armfleet service: a library (sync and async), Tk and terminal controllers,
and a live watcher.

    from clients import ArmfleetClient
    with ArmfleetClient("http://127.0.0.1:8000") as arm:
        ack = arm.increment(0, "elbow_joint", 0.1)

The UIs (`clients.tk_controller`, `clients.tui`, `clients.watch`) are imported on demand.
"""

from clients._core import (
    ArmfleetError,
    Backoff,
    BatchAck,
    BatchStates,
    CommandAck,
    CommandRejected,
    Conflict,
    ConnectionStatus,
    Info,
    InvalidRequest,
    JointInfo,
    NotFound,
    NotReady,
    PayloadTooLarge,
    ResetResult,
    SimStatus,
    Unreachable,
    WorldState,
)
from clients.async_client import AsyncArmfleetClient, AsyncWorldSession
from clients.client import ArmfleetClient, WorldSession

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
    "Info",
    "InvalidRequest",
    "JointInfo",
    "NotFound",
    "NotReady",
    "PayloadTooLarge",
    "ResetResult",
    "SimStatus",
    "Unreachable",
    "WorldSession",
    "WorldState",
]
