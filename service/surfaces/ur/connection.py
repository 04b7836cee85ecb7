"""One client connection of one world's UR ports, as the world counts it: the bookkeeping the
Dashboard and script-port protocols share (the world is told when it opens and closes, so a
world that is not lent refuses it, and input owners are released when it goes)."""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from service.surfaces.ur.world_robot import WorldRobot


class RobotConnection(asyncio.Protocol):
    """A text connection of `robot` (runs on the UR event loop); subclasses read the data."""

    def __init__(self, robot: WorldRobot) -> None:
        self.robot = robot
        self.transport: asyncio.Transport | None = None
        self._buffer = bytearray()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # a stream transport (uvloop's is not an asyncio.Transport subclass: endpoints.py)
        self.transport = cast(asyncio.Transport, transport)
        self.robot.opened(self)

    def connection_lost(self, exc: Exception | None) -> None:
        self.robot.closed(self)
