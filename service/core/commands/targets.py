"""Target commands: the seed's Up/Down (`increment`), JointState-shaped targets (`set_targets`)
and full rows for many worlds at one tick boundary (`set_many`). The first two replay as the
third: recorded as the rows they made and the joints they named."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import ConfigDict, Field, ValidationError, model_validator
from pydantic_core import PydanticCustomError

from service.core.commands.base import Announcement, Command, Door, result_ack
from service.core.commands.fields import (
    Delta,
    FiniteFloat,
    JointKey,
    JointRef,
    Paired,
    Strict,
    WorldId,
    default_spec,
    equal_lengths,
    joint_names,
    non_null,
    paired_config,
)
from service.core.errors import BadCommand
from service.core.sim import arithmetic, rules
from service.core.sim.loop_types import CommandResult
from service.core.sim.rules import BadJointState, joint_state
from service.core.sim.types import NJOINT, RobotSpec

__all__ = ["Increment", "SetMany", "SetTargets"]


# -- request bodies (HTTP; the WebSocket ops validate with the same models) ----------------------
#
# The JSON Schema of every request states every rule the server enforces (joint names, equal
# lengths, which of increment's two shapes, strict integers), so that what the schema calls
# valid is accepted and what it calls invalid is refused: schemathesis holds us to that
# (tests/test_contract.py).

MAX_BATCH_WORLDS = 64  # worlds per POST /v1/targets; the schema lists every allowed length


class IncrementRequest(Strict):
    """One joint (`joint` + `delta`) or several (`deltas`): the seed's Up/Down buttons."""

    joint: JointRef | None = None
    delta: Delta | None = None
    deltas: Annotated[dict[JointKey, Delta], Field(min_length=1)] | None = None

    @staticmethod
    def _schema(schema: dict[str, Any]) -> None:
        # Exactly one of the two shapes, and no nulls (the validator below refuses them too).
        props = schema.pop("properties")
        plain = {k: non_null(v) for k, v in props.items()}
        schema.pop("additionalProperties", None)
        schema["oneOf"] = [
            {
                "title": "one joint",
                "type": "object",
                "properties": {"joint": plain["joint"], "delta": plain["delta"]},
                "required": ["joint", "delta"],
                "additionalProperties": False,
            },
            {
                "title": "several joints",
                "type": "object",
                "properties": {"deltas": plain["deltas"]},
                "required": ["deltas"],
                "additionalProperties": False,
            },
        ]
        schema["examples"] = [
            {"joint": "elbow_joint", "delta": 0.1},
            {"deltas": {"elbow_joint": 0.1, "finger_joint": -0.1}},
        ]

    model_config = ConfigDict(extra="forbid", json_schema_extra=_schema)

    @model_validator(mode="before")
    @classmethod
    def _no_nulls(cls, data: Any) -> Any:
        if isinstance(data, dict):
            for key in ("joint", "delta", "deltas"):
                if key in data and data[key] is None:
                    raise ValueError(f"`{key}` may be left out but not null")
        return data

    @model_validator(mode="after")
    def _one_form(self) -> IncrementRequest:
        single = self.joint is not None or self.delta is not None
        if single == (self.deltas is not None):
            raise ValueError("give either `joint` and `delta`, or `deltas`")
        if single and (self.joint is None or self.delta is None):
            raise ValueError("`joint` and `delta` go together")
        return self

    def as_mapping(self) -> dict[str | int, float]:
        if self.deltas is not None:
            return dict(self.deltas)
        assert self.joint is not None and self.delta is not None
        return {self.joint: self.delta}


class JointTargets(Strict):
    """sensor_msgs/JointState-shaped: a subset of names is allowed, others keep their targets;
    with no names (left out or empty), one position per joint in joint order, as the seed's
    Isaac subscriber read them. The rule is service.core.sim.rules.joint_state."""

    name: list[JointKey] = Field(
        default_factory=list, max_length=NJOINT, json_schema_extra={"uniqueItems": True}
    )
    position: list[FiniteFloat] = Field(min_length=1, max_length=NJOINT)

    @staticmethod
    def _schema(schema: dict[str, Any]) -> None:
        branches = equal_lengths("name", "position", range(1, NJOINT + 1))
        for branch in branches:
            branch["required"] = ["name"]
        nameless = {"minItems": NJOINT, "maxItems": NJOINT}
        branches.append({"properties": {"name": {"maxItems": 0}, "position": nameless}})
        schema["oneOf"] = branches
        # A joint named twice, once by name and once by index ("5" is wrist_3_joint), is a
        # repeat too: JSON Schema's uniqueItems cannot see it, so each such pair is excluded.
        schema["not"] = {
            "anyOf": [
                {
                    "required": ["name"],
                    "properties": {
                        "name": {
                            "allOf": [{"contains": {"const": n}}, {"contains": {"const": str(i)}}]
                        }
                    },
                }
                for i, n in enumerate(joint_names())
            ]
        }
        schema["examples"] = [
            {"name": ["elbow_joint", "finger_joint"], "position": [1.2, 0.35]},
            {"position": [0, -1.57, 1.57, -1.57, -1.57, 0, 0]},
        ]

    # JointState also carries header/velocity/effort: allowed, and ignored
    model_config = ConfigDict(extra="allow", json_schema_extra=_schema)

    @model_validator(mode="before")
    @classmethod
    def _the_rule(cls, data: Any) -> Any:
        """The one JointState rule, so that HTTP refuses with the same words as every surface."""
        if isinstance(data, dict):
            try:
                joint_state(default_spec(), data.get("name", []), data.get("position"))
            except BadJointState as exc:
                raise PydanticCustomError("joint_state", "{rule}", {"rule": str(exc)}) from None
        return data


class BatchTargets(Paired):
    """Full 7-joint targets for many worlds in one request, applied at one tick boundary."""

    PAIR = ("worlds", "position")
    worlds: list[WorldId] = Field(
        min_length=1,
        max_length=MAX_BATCH_WORLDS,
        json_schema_extra={"uniqueItems": True},
        description=f"distinct world ids, at most {MAX_BATCH_WORLDS} per request",
    )
    position: list[Annotated[list[FiniteFloat], Field(min_length=7, max_length=7)]] = Field(
        min_length=1, max_length=MAX_BATCH_WORLDS, description="one row of 7 targets per world"
    )

    model_config = paired_config(
        PAIR,
        MAX_BATCH_WORLDS,
        {"worlds": [0, 1], "position": [[0, -1.57, 1.57, -1.57, -1.57, 0, 0]] * 2},
    )


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
class _OneWorld(Command[CommandResult], moves=True):
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
        return door.loop.commands.stage_rows(
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
class Increment(_OneWorld, kind="increment", op="increment", http=("increments",)):
    """Add to the named joints' latest targets (`values`: deltas), clamped to range: the seed's
    Up/Down."""

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
class SetTargets(_OneWorld, kind="set_targets", op="set_targets", http=("targets",)):
    """JointState-shaped targets for one world: the named joints move, the others keep theirs."""

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
class SetMany(Command[list[CommandResult]], kind="set_many", moves=True):
    """Full targets for many worlds, staged together for one tick boundary; with `joints`
    (indices, a replay's) only those joints of each row change."""

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

        return door.loop.commands.stage_rows(self.worlds, update, named)

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
