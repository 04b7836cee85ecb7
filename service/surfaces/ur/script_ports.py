"""The primary, secondary and real-time ports (30001-30003): URScript in, log messages out.

On a robot these take URScript and stream state packages. armfleet runs no URScript; what it
reads on these ports is one of two things:
- a program (`def name(): ... end`): ur_rtde's control script is recognised and run natively
  (control_script.py, script_runner.py); any other program is refused;
- lines, each one call of the small set `urscript.SIGNATURES` names (movej, movel, speedj,
  speedl, servoj, stopj, stopl, set_tcp, set_payload), carried out by script_lines.py.
Whatever is refused is never silently dropped: a line in the service log and, to every client
of the world's primary and secondary ports, a robot message package (type 20, a text message)
saying what and why, the place where a robot's log messages come. Nothing else is streamed.
"""

from __future__ import annotations

import logging
import re
from typing import TYPE_CHECKING

from service.surfaces.ur import control_script, script_lines, script_runner, urscript
from service.surfaces.ur.connection import RobotConnection

if TYPE_CHECKING:
    from service.surfaces.ur.world_robot import WorldRobot

log = logging.getLogger("armfleet.ur")
_MAX_PROGRAM = 1 << 20  # bytes of one program (ur_rtde's script is about 42 kB)
_PROGRAM_END = re.compile(rb"\n[ \t]*end[ \t]*\r?\n?\s*$")
LOG_PORTS = (30001, 30002)


class ScriptSession(RobotConnection):
    """One client of port 30001, 30002 or 30003 of one world (the UR event loop)."""

    def __init__(self, robot: WorldRobot, port: int) -> None:
        super().__init__(robot)
        self.port = port

    def data_received(self, data: bytes) -> None:
        self._buffer += data
        if len(self._buffer) > _MAX_PROGRAM:
            self._buffer.clear()
            return self.refuse("a program longer than 1 MiB")
        if self._buffer.lstrip().startswith(b"def "):
            if _PROGRAM_END.search(self._buffer):
                program = self._buffer.decode("utf-8", "replace")
                self._buffer.clear()
                self._program(program)
            return
        while (end := self._buffer.find(b"\n")) >= 0:
            line = bytes(self._buffer[:end]).decode("utf-8", "replace").strip()
            del self._buffer[: end + 1]
            if line and not line.startswith("#"):
                self._line(line)
            if self._buffer.lstrip().startswith(b"def "):
                return self.data_received(b"")

    def _program(self, program: str) -> None:
        if not control_script.is_control_script(program):
            name = program.split("(", 1)[0].split()[-1]
            return self.refuse(f"program {name}(): armfleet runs no URScript programs")
        try:
            script = control_script.recognise(program)
        except (control_script.NotControlScript, urscript.ScriptError) as exc:
            return self.refuse(f"rtde_control(): {exc}")
        script_runner.start_script(self.robot, script)

    def _line(self, line: str) -> None:
        try:
            script_lines.run(self.robot, urscript.parse_line(line))
        except script_lines.Refused as exc:
            self.refuse(str(exc))
        except urscript.ScriptError as exc:
            self.refuse(f"{line[:60]!r}: {exc}")

    def refuse(self, why: str) -> None:
        log.warning("world %d port %d refused: %s", self.robot.world, self.port, why)
        self.robot.log_message(f"armfleet refused: {why}")

    def send(self, data: bytes) -> None:
        t = self.transport
        if self.port in LOG_PORTS and t is not None and not t.is_closing():
            t.write(data)

    def refuse_connection(self, why: str) -> None:
        log.info("world %d port %d connection closed: %s", self.robot.world, self.port, why)
        if self.transport is not None:
            self.transport.abort()
