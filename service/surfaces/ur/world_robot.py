"""One world's controller as its connections see it: address, state, clients, input owners.

Why a module of its own: the connections (RTDE, Dashboard, script ports) and the listeners
(endpoints.py) both hold it; it knows the listeners only as a `Fleet` (the latest frame's values,
the payloads, the count of streaming connections), and the running control script
and the URScript lines' speed loop only as `Program` and `Loop`: script_runner.start_script
and script_lines.line_speed make them, so no import runs in a circle (type-only ones too).
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Protocol

from service.core.sim.safety import SafetyTable
from service.surfaces.ur.controller import Controller, ProgramState
from service.surfaces.ur.robot_messages import robot_message
from service.surfaces.ur.rtde_frame import Frame, FrameValues
from service.surfaces.ur.rtde_outputs import WorldTick
from service.surfaces.ur.rtde_pacer import Pacers

if TYPE_CHECKING:
    from service.surfaces.ur.motion import Motion

log = logging.getLogger("armfleet.ur")
NO_PAYLOAD = (0.0, 0.0, 0.0, 0.0)
GAP_WARN_S = 1.0  # an RTDE client this long without a package is logged (ur_rtde quits at 2.5)
GAP_WARN_EVERY_S = 5.0  # at most one such line per world this often (64 streams stall at once)


class Fleet(Protocol):
    """What a world's controller reads of the listeners that hold it (endpoints.Endpoints)."""

    frame: Frame | None
    safety: SafetyTable
    motion: Motion | None
    payloads: dict[int, tuple[float, ...]]
    streaming: int
    pacers: Pacers

    def values(self) -> FrameValues | None: ...


class Session(Protocol):
    def refuse_connection(self, why: str) -> None: ...

    def send(self, data: bytes) -> None: ...


class Program(Protocol):
    """ur_rtde's control script while it runs (script_runner.ScriptRunner)."""

    alive: bool

    def on_inputs(self) -> None: ...

    def end(self, why: str, halt: bool = True) -> None: ...


class Loop(Protocol):
    """The speed loop of URScript's speedj/speedl lines (script_lines.LineSpeed)."""

    def end(self) -> None: ...


class WorldRobot:
    """One world's controller: its address, state, connections and input-variable owners."""

    def __init__(self, world: int, address: str, fleet: Fleet) -> None:
        self.world, self.address, self.fleet = world, address, fleet
        self.controller = Controller(world, fleet.safety)
        self.sessions: set[Session] = set()
        self.open = True  # accepting connections (leases: while lent)
        self.owner: str | None = None  # the lease holding it (leases on)
        self._writers: dict[str, Session] = {}  # input variable → the session writing it
        self._view: WorldTick | None = None
        self._view_version = -1
        self._view_at: float | None = None  # the pacer round that last asked (view)
        self._sent_closed = 0  # RTDE data packages of the connections closed so far
        self.runner: Program | None = None  # ur_rtde's control script, while it runs
        self.speed_loop: Loop | None = None  # script_lines.line_speed makes it
        self.longest_gap = 0.0  # s: the longest a started RTDE stream went without a package
        self._warned_at = -GAP_WARN_EVERY_S  # time.monotonic() of the last line saying so

    def opened(self, session: Session) -> None:
        if not self.open:
            session.refuse_connection(f"world {self.world} is not lent (leases are on)")
            return
        self.sessions.add(session)

    def closed(self, session: Session) -> None:
        self.sessions.discard(session)
        self._sent_closed += getattr(session, "sent", 0)
        for name in [n for n, s in self._writers.items() if s is session]:
            del self._writers[name]

    def rtde_sent(self) -> int:
        """RTDE data packages sent to this world's clients (open and closed connections):
        counted per connection (RtdeSession.sent), summed only when asked."""
        open_now = tuple(self.sessions)  # one copy under the GIL (the UR thread adds and drops)
        return self._sent_closed + sum(getattr(s, "sent", 0) for s in open_now)

    def may_write(self, name: str, session: Session) -> bool:
        return self._writers.get(name, session) is session

    def hold_inputs(self, names: list[str], session: Session) -> None:
        for name in names:
            self._writers[name] = session

    def streaming(self, delta: int) -> None:
        self.fleet.streaming += delta

    def rtde_gap(self, gap: float, skipped: int) -> None:
        """A started RTDE stream sent a package `gap` s after its last one, `skipped`
        packages skipped meanwhile for a client socket that was full. Kept (GET /v1/ur) and,
        from GAP_WARN_S, logged with the side that was slow."""
        self.longest_gap = max(self.longest_gap, gap)
        if gap < GAP_WARN_S:
            return
        now = time.monotonic()
        if now - self._warned_at >= GAP_WARN_EVERY_S:
            self._warned_at = now
            why = (
                f"the client read nothing ({skipped} packages skipped for its full socket)"
                if skipped
                else "the UR thread had no turn for that long (cores, or a long call on it)"
            )
            log.warning(
                "world %d: an RTDE client got no package for %.2f s (ur_rtde drops its "
                "connection after 2.5 s): %s", self.world, gap, why,
            )  # fmt: skip

    def view(self, now: float | None = None) -> WorldTick | None:
        """This world at the latest frame (shared by its sessions until the frame's values,
        the controller or the payload change). `now`: the pacer round asking (the event
        loop's time of its send); the world's other streams of the same round get the view
        it answered without looking again. Why: ur_rtde's two interfaces stream 500 Hz each,
        so every round asked twice per world, and nothing on this thread changes a view
        within a round (a frame the sim thread hands over meanwhile goes out 2 ms later, at
        the next round, as one arriving just after the round would)."""
        if now is not None and now == self._view_at and self._view is not None:
            return self._view
        self._view_at = now
        values = self.fleet.values()
        if values is None:
            return None
        v = self._view
        payload = self.fleet.payloads.get(self.world, NO_PAYLOAD)
        # the payload is read apart from the frames: a paused world gets no new frame, so a
        # change of it must renew the view by itself (the TCP offset renews the values)
        if (
            v is None
            or v.values is not values
            or v.payload != payload
            or self._view_version != self.controller.version
        ):
            v = self._view = WorldTick(values, self.world, self.controller, payload)
            self._view_version = self.controller.version
        return v

    def close_all(self, why: str) -> None:
        self.end_script(why)
        for session in list(self.sessions):
            session.refuse_connection(why)
        self.sessions.clear()
        self._writers.clear()

    # -- programs (script ports, RTDE registers) and safety --------------------------------

    @property
    def motion(self) -> Motion:
        motion = self.fleet.motion
        if motion is None:
            raise RuntimeError("the UR surface has not started")
        return motion

    def end_script(self, why: str) -> None:
        if self.runner is not None:
            self.runner.end(why)
            self.runner = None

    def inputs_changed(self) -> None:
        """An RTDE input package was applied: the running control script reads it."""
        if self.runner is not None:
            if self.runner.alive:
                self.runner.on_inputs()
            else:
                self.runner = None

    def end_speed_loop(self) -> None:
        if self.speed_loop is not None:
            self.speed_loop.end()

    def protective_stop(self, why: str) -> None:
        """The program's own cause (triggerProtectiveStop): the program ends, then the core's
        `protective_stop` command holds the arm where it is and sets the world's safety mode
        in one step; `stopped` follows, as for any other cause."""
        if self.controller.safety_mode.name == "PROTECTIVE_STOP":
            return
        self.end_script(f"protective stop: {why}")
        self.end_speed_loop()
        self.motion.protective_stop(self.world, why)

    def stopped(self, why: str) -> None:
        """The world was protective-stopped, by whatever cause (the core's clearance watch of
        every world's targets, or `protective_stop` above): the program ends, the controller
        says STOPPED, the primary and secondary clients get the robot's message. The arm is
        held by then, and the core refuses every command that would move it until the
        Dashboard's `unlock protective stop` (5 s later at the earliest) or a reset."""
        self.end_script(f"protective stop: {why}")
        self.end_speed_loop()
        self.controller.stopped()
        self.log_message(f"Protective stop: {why}")

    def log_message(self, text: str) -> None:
        """A robot message to every client of the primary and secondary ports."""
        data = robot_message(text)
        for session in list(self.sessions):
            session.send(data)

    @property
    def program_running(self) -> bool:
        return self.controller.program is ProgramState.PLAYING
