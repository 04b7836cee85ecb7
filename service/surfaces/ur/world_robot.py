"""One world's controller as its connections see it: address, state, sessions, input owners.

Why a module of its own: the sessions (RTDE, Dashboard, script ports) and the listeners
(endpoints.py) both hold it; it knows the listeners only as a `Fleet` (the latest frame, the
kinematics, the payloads, the count of streaming sessions), so no import runs in a circle.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Protocol

from service.surfaces.ur.controller import Controller, ProgramState
from service.surfaces.ur.rtde_outputs import Frame, WorldTick
from service.surfaces.ur.tcp_pose import ToolKinematics

if TYPE_CHECKING:
    from service.surfaces.ur.control_script import ControlScript
    from service.surfaces.ur.motion import Motion
    from service.surfaces.ur.script_lines import LineSpeed
    from service.surfaces.ur.script_runner import ScriptRunner

log = logging.getLogger("armfleet.ur")
NO_PAYLOAD = (0.0, 0.0, 0.0, 0.0)


class Fleet(Protocol):
    """What a world's controller reads of the listeners that hold it (endpoints.Endpoints)."""

    frame: Frame | None
    kin: ToolKinematics
    motion: Motion | None
    payloads: dict[int, tuple[float, ...]]
    streaming: int


class Session(Protocol):
    def refuse_connection(self, why: str) -> None: ...

    def send(self, data: bytes) -> None: ...


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
        self.runner: ScriptRunner | None = None  # ur_rtde's control script, while it runs
        self._line_speed: LineSpeed | None = None

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
        if v is None or v.frame is not frame or self._view_version != self.controller.version:
            payload = self.fleet.payloads.get(self.world, NO_PAYLOAD)
            v = self._view = WorldTick(frame, self.world, self.fleet.kin, self.controller, payload)
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

    def start_script(self, script: ControlScript) -> None:
        """ur_rtde's control script arrived: it replaces the running program, if it may run."""
        from service.surfaces.ur.script_runner import ScriptRunner

        self.end_script("a new program replaced it")
        if self._line_speed is not None:
            self._line_speed.end()
        ctl = self.controller
        if not ctl.can_run_script():
            log.warning(
                "world %d: control script not started: robot mode %s, safety mode %s",
                self.world, ctl.robot_mode.name, ctl.safety_mode.name,
            )  # fmt: skip
            self.log_message("program not started: the robot is not ready (mode, safety)")
            return
        self.runner = ScriptRunner(self, script, self.motion)
        self.runner.start()

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

    def line_speed(self) -> LineSpeed:
        from service.surfaces.ur.script_lines import LineSpeed

        if self._line_speed is None:
            self._line_speed = LineSpeed(self)
        return self._line_speed

    def protective_stop(self, why: str) -> None:
        """The arm stops where it is, the program ends, the safety mode says so until the
        Dashboard's `unlock protective stop` (5 s later at the earliest)."""
        if self.controller.safety_mode.name == "PROTECTIVE_STOP":
            return
        log.warning("world %d: protective stop: %s", self.world, why)
        self.end_script(f"protective stop: {why}")
        if self._line_speed is not None:
            self._line_speed.end()
        self.controller.protective_stop()
        self.motion.halt(self.world)
        self.log_message(f"Protective stop: {why}")

    def log_message(self, text: str) -> None:
        """A robot message to every client of the primary and secondary ports."""
        from service.surfaces.ur.script_ports import robot_message

        data = robot_message(text)
        for session in list(self.sessions):
            session.send(data)

    @property
    def program_running(self) -> bool:
        return self.controller.program is ProgramState.PLAYING
