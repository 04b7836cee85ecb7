"""Recognising ur_rtde's control script when a client uploads it to a script port.

`RTDEControlInterface` sends one URScript program (`def rtde_control(): ... end`) to port 30003
(30002 with some flags) and then drives it through RTDE registers. armfleet runs no URScript:
it recognises that program and carries out its commands natively (script_runner.py). What
identifies it: the `def rtde_control():` header, the `# HEADER_BEGIN` / `# HEADER_END` block
with `rtde_cmd()`, and the banner the script prints when it starts, which carries its build
date. Known banners are the versions whose command numbers and registers script_commands.py
decodes; another `rtde_control` program is refused with a line naming the banner it has.

Two things ur_rtde fills in before sending: the register offset (0, or 24 with
FLAG_UPPER_RANGE_REGISTERS) after `reg_offset_int =`, and for moveJ/moveL/movePath with a path
the path itself in `exec_move_path()` (lines of `movej`/`movel`, read with urscript.py).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass

from service.surfaces.ur import urscript

HEADER = "def rtde_control():"
# The banner of each known build → the ur_rtde releases that ship it. Every 1.6.x wheel of the
# registry for CPython 3.11 (1.6.0 ... 1.6.5) sends a script with this banner, as its own
# `script_client.ScriptClient.sendScript()` builds it (tests/test_ur_scripts.py); their
# command numbers and registers are the same, so one decoder serves them all.
KNOWN_BANNERS = {"14.02.2024-12:23": "ur_rtde 1.6.x"}
# Under one banner the scripts differ a little, enough to name the releases in the log: 1.6.2
# added commands 66-71 (directTorque, getMassMatrix, ...: no-ops in the script, which its
# client uses only from 1.6.2), and 1.6.3 dropped the text messages of
# getActualToolFlangePose. (marker in the script, present?) → releases, first match wins.
RELEASES = (
    (("elif cmd == 66:", False), ("1.6.0", "1.6.1")),
    (('textmsg("get_actual_tool_flange_pose")', True), ("1.6.2",)),
    (("elif cmd == 66:", True), ("1.6.3", "1.6.4", "1.6.5")),
)
_BANNER = re.compile(r'textmsg\("RTDE Control Script Loaded \(([^)]*)\)"\)')
_OFFSET = re.compile(r"reg_offset_int\s*=\s*(?:#[^\n]*\n)?\s*(\d+)")
_PATH = re.compile(
    r'def exec_move_path\(\):\s*\n\s*textmsg\("exec_move_path"\)\s*\n(.*?)\n\s*end\s*\n', re.S
)


class NotControlScript(ValueError):
    """A program that is not a known ur_rtde control script (the reason names what is off)."""


@dataclass(frozen=True)
class ControlScript:
    """A recognised control script: its banner (build), the ur_rtde releases that send it,
    the register offset, the moves injected into exec_move_path, and a digest of its text."""

    banner: str
    releases: tuple[str, ...]
    register_offset: int
    path: tuple[urscript.Call, ...]
    digest: str

    @property
    def versions(self) -> str:
        """The releases as the log names them: "ur_rtde 1.6.x: 1.6.3, 1.6.4, 1.6.5"."""
        return f"{KNOWN_BANNERS[self.banner]}: {', '.join(self.releases) or 'unknown'}"


def is_control_script(program: str) -> bool:
    return program.lstrip().startswith(HEADER)


def recognise(program: str) -> ControlScript:
    """The ControlScript of `program`; NotControlScript when it is not one armfleet knows."""
    if not is_control_script(program):
        raise NotControlScript("the program does not start with `def rtde_control():`")
    if "# HEADER_BEGIN" not in program or "def rtde_cmd():" not in program:
        raise NotControlScript("no `# HEADER_BEGIN` block with rtde_cmd(): not ur_rtde's script")
    banner = _BANNER.search(program)
    if banner is None:
        raise NotControlScript("no 'RTDE Control Script Loaded (...)' banner")
    build = banner.group(1)
    if build not in KNOWN_BANNERS:
        raise NotControlScript(
            f"ur_rtde control script of build {build!r}: armfleet knows "
            f"{', '.join(f'{b} ({v})' for b, v in KNOWN_BANNERS.items())}"
        )
    offset = _OFFSET.search(program)
    reg = int(offset.group(1)) if offset else 0
    if reg not in (0, 24):
        raise NotControlScript(f"register offset {reg} (ur_rtde uses 0 or 24)")
    path: list[urscript.Call] = []
    body = _PATH.search(program)
    if body is not None:
        for line in body.group(1).splitlines():
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            path.append(urscript.parse_line(line))
    digest = hashlib.sha256(program.encode()).hexdigest()[:16]
    return ControlScript(build, _releases(program), reg, tuple(path), digest)


def _releases(program: str) -> tuple[str, ...]:
    """Which ur_rtde releases send `program` (of a known banner): RELEASES' first match."""
    for (marker, present), releases in RELEASES:
        if (marker in program) == present:
            return releases
    return ()
