"""The primary, secondary and real-time ports (30001-30003): accepted and kept, nothing sent.

On a robot these take URScript and stream robot state packages. armfleet does not interpret
URScript here yet: a connection is accepted and held open, and what it sends is read and
dropped (counted, and said once in the log), so a client that connects to every port of a
controller (ur_rtde's script client does) finds them, and none gets bytes it would misread.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from service.surfaces.ur.world_robot import WorldRobot

log = logging.getLogger("armfleet.ur")


class ScriptSession(asyncio.Protocol):
    """One client of port 30001, 30002 or 30003 of one world (the UR event loop)."""

    def __init__(self, robot: WorldRobot, port: int) -> None:
        self.robot, self.port = robot, port
        self.transport: asyncio.Transport | None = None
        self.received = 0  # bytes read and dropped

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.robot.opened(self)

    def connection_lost(self, exc: Exception | None) -> None:
        self.robot.closed(self)

    def data_received(self, data: bytes) -> None:
        if not self.received:
            log.warning(
                "world %d port %d: URScript is not run by armfleet yet; %d bytes dropped "
                "(further data on this connection is dropped silently)",
                self.robot.world,
                self.port,
                len(data),
            )
        self.received += len(data)

    def refuse_connection(self, why: str) -> None:
        log.info("world %d port %d connection closed: %s", self.robot.world, self.port, why)
        if self.transport is not None:
            self.transport.abort()
