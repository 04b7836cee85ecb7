"""One world's controller as its connections see it: address, state, connections, input owners.

Why a module of its own: the connections (RTDE, Dashboard, script ports) and the listeners
(endpoints.py) both hold it; it knows the listeners only as a `Fleet` (the latest frame, the
kinematics, the payloads, the count of streaming connections), so no import runs in a circle.
"""

from __future__ import annotations

from typing import Protocol

from service.surfaces.ur.controller import Controller
from service.surfaces.ur.rtde_outputs import Frame, WorldTick
from service.surfaces.ur.tcp_pose import ToolKinematics

NO_PAYLOAD = (0.0, 0.0, 0.0, 0.0)


class Fleet(Protocol):
    """What a world's controller reads of the listeners that hold it (endpoints.Endpoints)."""

    frame: Frame | None
    kin: ToolKinematics
    payloads: dict[int, tuple[float, ...]]
    streaming: int


class Session(Protocol):
    def refuse_connection(self, why: str) -> None: ...


class WorldRobot:
    """One world's controller: its address, state, connections and input-variable owners."""

    def __init__(self, world: int, address: str, fleet: Fleet) -> None:
        self.world, self.address, self.fleet = world, address, fleet
        self.controller = Controller(world)
        self.sessions: set[Session] = set()
        self.open = True  # accepting connections (leases: while lent)
        self.owner: str | None = None  # the lease holding it (leases on)
        self._writers: dict[str, Session] = {}  # input variable → the session writing it
        self._view: WorldTick | None = None
        self._view_version = -1

    def opened(self, session: Session) -> None:
        if not self.open:
            session.refuse_connection(f"world {self.world} is not lent (leases are on)")
            return
        self.sessions.add(session)

    def closed(self, session: Session) -> None:
        self.sessions.discard(session)
        for name in [n for n, s in self._writers.items() if s is session]:
            del self._writers[name]

    def may_write(self, name: str, session: Session) -> bool:
        return self._writers.get(name, session) is session

    def hold_inputs(self, names: list[str], session: Session) -> None:
        for name in names:
            self._writers[name] = session

    def streaming(self, delta: int) -> None:
        self.fleet.streaming += delta

    def view(self) -> WorldTick | None:
        """This world at the latest frame (shared by its sessions until the frame or the
        controller changes)."""
        frame = self.fleet.frame
        if frame is None:
            return None
        v = self._view
        payload = self.fleet.payloads.get(self.world, NO_PAYLOAD)
        # the payload is polled apart from the frames: a paused world gets no new frame, so a
        # changed payload must renew the view by itself
        if (
            v is None
            or v.frame is not frame
            or v.payload != payload
            or self._view_version != self.controller.version
        ):
            v = self._view = WorldTick(frame, self.world, self.fleet.kin, self.controller, payload)
            self._view_version = self.controller.version
        return v

    def close_all(self, why: str) -> None:
        for session in list(self.sessions):
            session.refuse_connection(why)
        self.sessions.clear()
        self._writers.clear()
