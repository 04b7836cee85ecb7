"""Target commands: the seed's Up/Down (`increment`), JointState-shaped targets (`set_targets`)
and full rows for many worlds at one tick boundary (`set_many`). The first two replay as the
third: recorded as the rows they made and the joints they named."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from pydantic import ValidationError

from service.core.commands import arithmetic, rules
from service.core.commands.base import Announcement, Command, Door, result_ack
from service.core.errors import BadCommand
from service.core.loop_types import CommandResult
from service.core.schemas import IncrementRequest, JointTargets
from service.core.types import RobotSpec

__all__ = ["Increment", "SetMany", "SetTargets"]


def _validation_detail(exc: ValidationError) -> str:
    """pydantic's errors as one line: `loc: msg; loc: msg`."""
    return "; ".join(
        f"{'.'.join(str(p) for p in err['loc']) or 'message'}: {err['msg']}" for err in exc.errors()
    )


def _model(model: Any, body: dict[str, Any]) -> Any:
    """A WebSocket op's body read by its HTTP twin's model: the same rules, the same words."""
    try:
        return model.model_validate(body)
    except ValidationError as exc:  # the detail names each field itself
        raise BadCommand("", _validation_detail(exc)) from None


@dataclass(frozen=True)
class _OneWorld(Command[CommandResult]):
    """A target command on one world's named joints (`values`: joint index → value); the
    subclass says how a value changes the latest row (`update`). Replayed as the rows it made:
    recorded targets after the command, with the joints it named."""

    world: int
    values: Mapping[int, float]

    @property
    def touches(self) -> Sequence[int]:
        return (self.world,)

    def update(self, spec: RobotSpec, row: np.ndarray) -> arithmetic.TargetUpdate:
        raise NotImplementedError

    def stage(self, door: Door, source: str) -> CommandResult:
        spec = door.spec
        return door.loop.stage_rows(
            [self.world], lambda _, row: self.update(spec, row), self.values
        )[0]

    def announce(self, door: Door, result: CommandResult) -> Announcement:
        worlds = np.array([result.world], dtype=np.int64)
        record = {"joints": list(self.values)}
        return Announcement(worlds, result.target[None, :], result.tick, record)

    def ack(self, door: Door, msg_id: Any, world: int, result: CommandResult) -> dict[str, Any]:
        return result_ack(msg_id, result)

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> Command[Any]:
        return SetMany.from_record(door, rec)


@dataclass(frozen=True)
class Increment(_OneWorld):
    """Add to the named joints' latest targets (`values`: deltas), clamped to range: the seed's
    Up/Down."""

    kind: ClassVar[str] = "increment"
    op: ClassVar[str | None] = "increment"
    http: ClassVar[tuple[str, ...]] = ("increments",)

    @classmethod
    def create(
        cls, door: Door, world: object, deltas: Mapping[str | int, float], field: str = "deltas"
    ) -> Increment:
        world = rules.world_id(world, door.nworld)
        values = arithmetic.resolve_joints(door.spec, deltas, field)
        arithmetic.check_deltas(door.spec, values)
        return cls(world, values)

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> Increment:
        req = _model(IncrementRequest, body)
        field = "deltas" if req.deltas is not None else "joint"
        return cls.create(door, world, req.as_mapping(), field)

    def update(self, spec: RobotSpec, row: np.ndarray) -> arithmetic.TargetUpdate:
        return arithmetic.increment(spec, row, self.values)


@dataclass(frozen=True)
class SetTargets(_OneWorld):
    """JointState-shaped targets for one world: the named joints move, the others keep theirs."""

    kind: ClassVar[str] = "set_targets"
    op: ClassVar[str | None] = "set_targets"
    http: ClassVar[tuple[str, ...]] = ("targets",)

    @classmethod
    def create(cls, door: Door, world: object, name: Any, position: Any) -> SetTargets:
        world = rules.world_id(world, door.nworld)
        return cls(world, rules.joint_state(door.spec, name, position))

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> SetTargets:
        req = _model(JointTargets, body)
        return cls.create(door, world, req.name, req.position)

    def update(self, spec: RobotSpec, row: np.ndarray) -> arithmetic.TargetUpdate:
        return arithmetic.replace_targets(spec, row, self.values)


@dataclass(frozen=True)
class SetMany(Command[list[CommandResult]]):
    """Full targets for many worlds, staged together for one tick boundary; with `joints`
    (indices, a replay's) only those joints of each row change."""

    kind: ClassVar[str] = "set_many"

    worlds: list[int]
    rows: np.ndarray
    joints: tuple[int, ...] | None = None

    @property
    def touches(self) -> Sequence[int] | None:
        return self.worlds

    @classmethod
    def create(
        cls,
        door: Door,
        worlds: Sequence[object],
        positions: Any,
        joints: Sequence[int] | None = None,
    ) -> SetMany:
        ids = rules.world_ids(worlds, door.nworld)
        njoint = len(door.spec.joints)
        try:
            rows = np.asarray(positions, dtype=np.float64)
        except (TypeError, ValueError):
            raise BadCommand("position", "position must be a list of rows of numbers") from None
        if rows.shape != (len(ids), njoint):
            raise BadCommand(
                "position",
                f"need one row of {njoint} targets per world: shape is {rows.shape}, "
                f"expected ({len(ids)}, {njoint})",
            )
        if not np.isfinite(rows).all():
            raise BadCommand("position", "values must be finite (no NaN or Inf)")
        named = None
        if joints is not None:
            named = tuple(int(j) for j in joints)
            if any(not 0 <= j < njoint for j in named):
                raise BadCommand("joints", f"joint indices are 0..{njoint - 1}, got {named}")
        return cls(ids, rows, named)

    def stage(self, door: Door, source: str) -> list[CommandResult]:
        spec = door.spec
        named = list(range(len(spec.joints))) if self.joints is None else list(self.joints)
        index = {w: i for i, w in enumerate(self.worlds)}

        def update(world: int, row: np.ndarray) -> arithmetic.TargetUpdate:
            values = dict(zip(named, self.rows[index[world], named].tolist(), strict=True))
            return arithmetic.replace_targets(spec, row, values)

        return door.loop.stage_rows(self.worlds, update, named)

    def announce(self, door: Door, result: list[CommandResult]) -> Announcement | None:
        if not result:
            return None
        worlds = np.array(self.worlds, dtype=np.int64)
        targets = np.stack([r.target for r in result])
        record = {} if self.joints is None else {"joints": list(self.joints)}
        return Announcement(worlds, targets, result[0].tick, record)

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> SetMany:
        """Recorded target commands replay as their rows after the command, named joints only."""
        return cls.create(door, rec["worlds"], rec["targets"], rec.get("joints"))
