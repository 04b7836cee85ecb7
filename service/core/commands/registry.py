"""The registration list: every command kind armfleet takes, in one tuple.

Everything that needs to know the kinds reads them from here: Control runs any of them, the
WebSocket op protocol finds a class by `op`, replay by `kind`, the recording's schema lists
`KINDS`, metrics count refusals of HTTP writes by the `http` path segments. Adding a command is
its module plus one line below.
"""

from __future__ import annotations

from service.core.commands.base import Command
from service.core.commands.cartesian import Jog, MoveLinear, MoveTcp
from service.core.commands.entities import SetEntities
from service.core.commands.params import SetParams
from service.core.commands.payload import SetPayload
from service.core.commands.randomize import Randomize
from service.core.commands.safety_stop import ProtectiveStop, UnlockProtectiveStop
from service.core.commands.targets import Increment, SetMany, SetTargets
from service.core.commands.tcp import SetTcp
from service.core.commands.trajectory.commands import (
    CancelTrajectory,
    ResumeTrajectory,
    StartTrajectory,
)
from service.core.commands.world import Reset, SetMode, Step

COMMANDS: tuple[type[Command], ...] = (
    Increment,
    SetTargets,
    SetMany,
    Reset,
    SetMode,
    Step,
    StartTrajectory,
    CancelTrajectory,
    ResumeTrajectory,
    SetEntities,
    SetParams,
    SetPayload,
    Randomize,
    SetTcp,
    MoveTcp,
    Jog,
    MoveLinear,
    ProtectiveStop,
    UnlockProtectiveStop,
)

BY_KIND: dict[str, type[Command]] = {c.kind: c for c in COMMANDS}
BY_OP: dict[str, type[Command]] = {c.op: c for c in COMMANDS if c.op is not None}
KINDS: tuple[str, ...] = tuple(BY_KIND)
BY_HTTP: dict[str, str] = {segment: c.kind for c in COMMANDS for segment in c.http}

assert len(BY_KIND) == len(COMMANDS), "two commands share a kind"
