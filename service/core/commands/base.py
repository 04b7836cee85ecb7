"""What a command is: one class per kind, owning its wire form, validation, staging and record.

A command object is made only by its own constructors (`create` from arguments, `from_wire`
from a WebSocket op's body, `from_record` from a recording), and every one of them validates
completely, naming the field and the limit, before anything is staged: an object that exists is
a valid command, and what it stages is trusted by the loop and the engines. `Control.run` stages
it under the order lock and announces an `Accepted` built from `announce`; the WebSocket op
protocol answers with `ack`; the recorder writes `Accepted` and replay calls `from_record`;
metrics count `kind`. The registry (`registry.py`) lists the classes.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Generic, TypeVar

import numpy as np

from service.core.errors import BadCommand
from service.core.sim.types import NJOINT, RobotSpec
from service.core.streams import wire

if TYPE_CHECKING:
    from service.core.commands.trajectory.manager import TrajectoryManager
    from service.core.sim.loop import SimLoop

R = TypeVar("R")

# Where a command came from: a label each surface declares (metrics and recordings tell
# surfaces apart by it). The core's own surfaces' labels:
HTTP, WS, BROWSER, REPLAY = "http", "ws", "browser", "replay"


class Door:
    """What a command stages through: the loop's command table and the trajectory runner.
    `Control` is the one door of a running service (it adds the order and the listeners)."""

    def __init__(self, loop: SimLoop, trajectories: TrajectoryManager) -> None:
        self.loop = loop
        self.trajectories = trajectories

    @property
    def spec(self) -> RobotSpec:
        return self.loop.spec

    @property
    def nworld(self) -> int:
        return self.loop.batch.nworld


@dataclass(frozen=True)
class Announcement:
    """What listeners hear of one accepted command, besides its source and kind.

    worlds: the worlds it changed                                            (k,) int64
    targets: those worlds' targets after it [rad]                            (k, 7) float64
    tick: the first tick stepped with it
    record: the command's own fields in its recorded form (JSON-able), read back by
        `from_record` (a mode's `mode`, a trajectory's `trajectory`, the `joints` named)
    """

    worlds: np.ndarray
    targets: np.ndarray
    tick: int
    record: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Accepted:
    """One accepted command as the listeners (metrics, the recorder) see it."""

    source: str
    kind: str
    worlds: np.ndarray
    targets: np.ndarray
    tick: int
    record: dict[str, Any] = field(default_factory=dict)


def no_worlds(tick: int, **record: Any) -> Announcement:
    """The announcement of a command that changes no world's targets (a mode switch)."""
    return Announcement(np.zeros(0, dtype=np.int64), np.zeros((0, NJOINT)), tick, record)


class Command(ABC, Generic[R]):
    """One kind of command. Subclasses name themselves in their class line and implement
    `stage`; the rest is optional:

        class Reset(Command[ResetResult], kind="reset", op="reset", http=("reset",)):

    kind: its name in metrics labels, recordings and the registry (spelled only in its module)
    op: its op on the JSON WebSocket protocol (`/v1/ws`, `/v1/ws/worlds/{w}`, `/v1/ws/view`),
        None when it has none; a command with an op implements `from_wire` and `ack`
    http: the last segments of its HTTP write paths (metrics count refusals by them)
    replayed: replay applies it at its recorded tick (a mode switch is not: replay steps)
    moves: it sets joint targets or starts a trajectory, so `Control.run` refuses it (409) on
        a protective-stopped world (core/sim/safety.py)
    What a class does not name it inherits from its base (`_OneWorld` names only `moves`).
    """

    kind: ClassVar[str]
    op: ClassVar[str | None] = None
    http: ClassVar[tuple[str, ...]] = ()
    replayed: ClassVar[bool] = True
    moves: ClassVar[bool] = False

    def __init_subclass__(
        cls,
        kind: str | None = None,
        op: str | None = None,
        http: tuple[str, ...] | None = None,
        replayed: bool | None = None,
        moves: bool | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init_subclass__(**kwargs)
        named = {"kind": kind, "op": op, "http": http, "replayed": replayed, "moves": moves}
        for name, value in named.items():
            if value is not None:
                setattr(cls, name, value)

    @property
    def touches(self) -> Sequence[int] | None:
        """The worlds it writes, known once it exists (`callers.Gate` checks them before it is
        staged); None: every world, or the whole service (a mode switch). A command that does
        not say touches every world, so only the administrator may run it."""
        return None

    @abstractmethod
    def stage(self, door: Door, source: str) -> R:
        """Stage it (the order lock is held); what the caller gets back."""

    def announce(self, door: Door, result: R) -> Announcement | None:
        """What the listeners hear (None: nothing to announce, e.g. nothing changed)."""
        return None

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> Command[Any]:
        """The command a WebSocket op's body (`op`, `id`, `world` removed) stands for."""
        raise BadCommand("op", f"{cls.kind} has no WebSocket op")

    def ack(self, door: Door, msg_id: Any, world: int, result: R) -> dict[str, Any]:
        """The WebSocket ack frame of a staged command."""
        return world_ack(msg_id, world)

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> Command[Any]:
        """The command replay applies for a recorded one (`Accepted` as the recorder wrote it)."""
        raise BadCommand("kind", f"{cls.kind} commands are not replayed")


def world_ack(msg_id: Any, world: int, **fields: Any) -> dict[str, Any]:
    """A command's WebSocket ack frame: the client's `id`, the world, then the command's own
    `fields` (a tick, what was normalised, ...)."""
    return {"op": "ack", "id": msg_id, "world": world, **fields}


def no_fields(kind: str, body: dict[str, Any]) -> None:
    """A WebSocket op that takes nothing besides op, id and world."""
    if body:
        raise BadCommand(next(iter(body)), f"{kind} takes no fields besides op, id and world")


def result_ack(msg_id: Any, result: Any) -> dict[str, Any]:
    """The ack of a target command (`CommandResult`): the world's target row and its tick."""
    return wire.ack(msg_id, result)
