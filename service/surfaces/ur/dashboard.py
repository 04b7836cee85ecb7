"""The Dashboard server (port 29999): text lines in, one line out each, as a UR10e answers.

The words are UR's (the Dashboard server's documentation for e-Series 5.x). What a command
changes is the world's `Controller` (controller.py), which RTDE reports: power on/off, brake
release, play/pause/stop of a loaded program, unlocking a protective stop (refused for 5 s
after the stop, as the robot does), restart safety. armfleet runs no URP programs: `load`
accepts any `.urp` name and `play` marks it running, so a program that checks the Dashboard
before it drives the arm over RTDE finds the states it expects; the arm is moved only through
RTDE (and armfleet's own surfaces). Commands match case-insensitively; anything else gets the
robot's "could not understand: '<line>'".
"""

from __future__ import annotations

import asyncio
import logging
import posixpath
from collections.abc import Callable
from typing import TYPE_CHECKING

from service.surfaces.ur import rtde_wire
from service.surfaces.ur.connection import RobotConnection
from service.surfaces.ur.controller import Controller, ProgramState

if TYPE_CHECKING:
    pass

log = logging.getLogger("armfleet.ur")
GREETING = "Connected: Universal Robots Dashboard Server"
VERSION = ".".join(map(str, rtde_wire.CONTROL_VERSION))
_MAX_LINE = 4096
_UNLOCK_TOO_SOON = (
    "Cannot unlock protective stop until 5s after occurrence. Always inspect cause of "
    "protective stop before unlocking"
)


def _program_name(ctl: Controller) -> str:
    return posixpath.basename(ctl.loaded_program) if ctl.loaded_program else "<unnamed>"


def _play(ctl: Controller) -> str:
    if not ctl.can_play():
        return "Failed to execute: play"
    ctl.set_program(ProgramState.PLAYING)
    return "Starting program"


def _pause(ctl: Controller) -> str:
    if ctl.program is not ProgramState.PLAYING:
        return "Failed to execute: pause"
    ctl.set_program(ProgramState.PAUSED)
    return "Pausing program"


def _stop(ctl: Controller) -> str:
    """ "Stopped" also when nothing runs: ur_rtde's reuploadScript() stops a script that has
    just ended and throws on any other answer."""
    if ctl.program is not ProgramState.STOPPED:
        ctl.set_program(ProgramState.STOPPED)
    return "Stopped"


def _brake_release(ctl: Controller) -> str:
    ctl.power_on()  # from power off the robot powers on first
    ctl.brake_release()
    return "Brake releasing"


def _unlock(ctl: Controller) -> str:
    return "Protective stop releasing" if ctl.unlock_protective_stop() else _UNLOCK_TOO_SOON


def _restart_safety(ctl: Controller) -> str:
    ctl.restart_safety()
    return "Restarting safety"


def _load(ctl: Controller, name: str) -> str:
    if not name.lower().endswith(".urp"):
        return f"File not found: {name}"
    ctl.loaded_program = name if name.startswith("/") else f"/programs/{name}"
    ctl.set_program(ProgramState.STOPPED)
    return f"Loading program: {name}"


def _loaded(ctl: Controller) -> str:
    return f"Loaded program: {ctl.loaded_program}" if ctl.loaded_program else "No program loaded"


# command (lower case, single spaces) → answer; each may change the controller
COMMANDS: dict[str, Callable[[Controller], str]] = {
    "power on": lambda c: (c.power_on(), "Powering on")[1],
    "power off": lambda c: (c.power_off(), "Powering off")[1],
    "brake release": _brake_release,
    "play": _play,
    "pause": _pause,
    "stop": _stop,
    "robotmode": lambda c: f"Robotmode: {c.robot_mode.name}",
    "safetymode": lambda c: f"Safetymode: {c.safety_mode.name}",
    "safetystatus": lambda c: f"Safetystatus: {c.safety_mode.name}",
    "programstate": lambda c: f"{c.program.name} {_program_name(c)}",
    "running": lambda c: f"Program running: {str(c.program is ProgramState.PLAYING).lower()}",
    "is in remote control": lambda c: "true",
    "unlock protective stop": _unlock,
    "close safety popup": lambda c: "closing safety popup",
    "close popup": lambda c: "closing popup",
    "polyscopeversion": lambda c: f"URSoftware {VERSION} (armfleet)",
    "version": lambda c: VERSION,
    "get loaded program": _loaded,
    "isprogramsaved": lambda c: f"true {_program_name(c)}",
    "get robot model": lambda c: "UR10",
    "get serial number": lambda c: f"20{c.world:08d}",
    "get operational mode": lambda c: "NONE",
    "restart safety": _restart_safety,
}
# commands with an argument: prefix → answer(controller, argument)
WITH_ARGUMENT: dict[str, Callable[[Controller, str], str]] = {
    "load": _load,
    "popup": lambda c, text: "showing popup",
    "addtolog": lambda c, text: (
        log.info("world %d addToLog: %r", c.world, text[:200]),
        "Added log message",
    )[1],
}


def answer(ctl: Controller, line: str) -> str:
    """The robot's answer to one command line (see the module docstring)."""
    words = line.split()
    key = " ".join(words).lower()
    if key in COMMANDS:
        return COMMANDS[key](ctl)
    if words and words[0].lower() in WITH_ARGUMENT:
        rest = line.strip()[len(words[0]) :].strip()
        if rest or words[0].lower() != "load":
            return WITH_ARGUMENT[words[0].lower()](ctl, rest)
    return f"could not understand: '{line}'"


class DashboardSession(RobotConnection):
    """One Dashboard client of one world (runs on the UR event loop)."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        assert self.transport is not None
        self.transport.write((GREETING + "\n").encode())

    def data_received(self, data: bytes) -> None:
        self._buffer += data
        while (end := self._buffer.find(b"\n")) >= 0 and self.transport is not None:
            raw = bytes(self._buffer[:end]).rstrip(b"\r")
            del self._buffer[: end + 1]
            line = raw.decode("utf-8", "replace")
            reply = answer(self.robot.controller, line)
            if self.transport.is_closing():
                return
            key = " ".join(line.split()).lower()
            if key == "quit":
                self.transport.write(b"Disconnected\n")
                self.transport.close()
                return
            self.transport.write((reply + "\n").encode())
        if len(self._buffer) > _MAX_LINE:
            self.refuse_connection(f"a line longer than {_MAX_LINE} bytes")

    def send(self, data: bytes) -> None:
        """Robot messages go to the script ports' clients, not to the Dashboard's."""

    def refuse_connection(self, why: str) -> None:
        log.warning("world %d Dashboard connection closed: %s", self.robot.world, why)
        if self.transport is not None:
            self.transport.abort()
