"""Entities: every named free body of the scene, in every world; `set_entity` writes their pose
and twist at one tick boundary, and `read` reads them back.

An entity is a body whose joint is a MuJoCo free joint: its pose is 7 numbers of the world's
qpos (position x y z [m], orientation w x y z) and its twist 6 of qvel (linear velocity [m/s] in
the world frame, angular velocity [rad/s] in the body's own frame, as MuJoCo stores a free
joint's). The writes are `StateWrite`s (service.core.sim.batch): every engine applies them already,
after the tick boundary's resets and before its targets, so this module needs no engine code.

Rules (each refusal names the field and the limit; one bad write refuses the whole command,
nothing is staged): `name` is an entity of the scene; every number finite; `position` inside the
scene's bounds (the model's custom numeric `armfleet_bounds`, x y z min then max, else the
model's statistic centre ± extent); `orientation` a quaternion with |norm − 1| <= 0.1, normalised
when it is not unit already (the ack lists it under `normalised`); |linear| <= 50 m/s,
|angular| <= 500 rad/s; at least one of the four fields.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import Field

from service.core.commands.base import Door, world_ack
from service.core.commands.fields import FiniteFloat, Strict, WorldId, example_config
from service.core.commands.writes import MAX_WRITES, ManyWrites, batch_config
from service.core.errors import BadCommand
from service.core.sim import rules
from service.core.sim.batch import StateWrite
from service.core.sim.entities import EntityTable, entity_table

__all__ = ["EntityState", "SetEntities"]

MAX_LINEAR = 50.0  # m/s
MAX_ANGULAR = 500.0  # rad/s
QUAT_TOLERANCE = 0.1  # |norm - 1| above this: refused; below: normalised
_UNIT = 1e-12  # a norm this close to 1 is taken as given
_FIELDS = ("position", "orientation", "linear", "angular")


# -- the wire form ------------------------------------------------------------------------


class EntityValues(Strict):
    """What to write of one entity: any of its pose and twist (at least one field)."""

    position: list[FiniteFloat] | None = Field(
        None, min_length=3, max_length=3, description="x y z [m], world frame"
    )
    orientation: list[FiniteFloat] | None = Field(
        None, min_length=4, max_length=4, description="quaternion w x y z (normalised if near)"
    )
    linear: list[FiniteFloat] | None = Field(
        None, min_length=3, max_length=3, description="linear velocity [m/s], world frame"
    )
    angular: list[FiniteFloat] | None = Field(
        None, min_length=3, max_length=3, description="angular velocity [rad/s], body frame"
    )

    model_config = example_config(
        {"position": [0.7, 0.1, 0.9], "orientation": [1, 0, 0, 0], "linear": [0, 0, 0]}
    )


class EntityState(Strict):
    """One entity as read (GET .../entities, and state frames that ask for entities)."""

    name: str
    position: list[float] = Field(description="x y z [m], world frame")
    orientation: list[float] = Field(description="quaternion w x y z")
    linear: list[float] = Field(description="linear velocity [m/s], world frame")
    angular: list[float] = Field(description="angular velocity [rad/s], body frame")


class EntityWrite(EntityValues):
    """One entity of one world, in a batch write."""

    world: WorldId
    name: str

    model_config = example_config({"world": 0, "name": "cube", "position": [0.7, 0.1, 0.9]})


class EntityWrites(Strict):
    """Entity writes for any worlds, all applied at one tick boundary (or none of them)."""

    writes: list[EntityWrite] = Field(min_length=1, max_length=MAX_WRITES)

    model_config = batch_config(
        {"world": 0, "name": "cube", "position": [0.7, 0.1, 0.9]},
        {"world": 1, "name": "cube", "angular": [0, 0, 2]},
    )


class EntityAck(Strict):
    tick: int = Field(description="the first tick stepped from the written state")
    worlds: list[int]
    normalised: list[str] = Field(description="orientations that were normalised, by field")


@dataclass(frozen=True)
class EntityResult:
    """The tick the writes take effect at, the worlds written, what was normalised."""

    tick: int
    worlds: list[int]
    normalised: list[str]


# -- validation ---------------------------------------------------------------------------


def _vector(value: Any, n: int, field: str) -> np.ndarray:
    if not isinstance(value, list | tuple) or len(value) != n:
        raise BadCommand(field, f"must be a list of {n} numbers, got {value!r}")
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise BadCommand(field, f"must be a list of {n} numbers, got {value!r}")
        if not math.isfinite(v):
            raise BadCommand(field, f"{v} is not finite (no NaN or Inf)")
    return np.array(value, dtype=np.float64)


def _checked(
    table: EntityTable, nworld: int, item: Mapping[str, Any], where: str, notes: list[str]
) -> list[StateWrite]:
    """One entity write → its StateWrites; BadCommand naming `where`.field otherwise."""
    if not isinstance(item, Mapping):
        raise BadCommand(where or "writes", "an entity write is an object")
    extra = set(item) - {"world", "name", *_FIELDS}
    if extra:
        raise BadCommand(f"{where}{sorted(extra)[0]}", f"unknown field; fields are {_FIELDS}")
    world = rules.world_id(item.get("world"), nworld, f"{where}world")
    e = table.index(item.get("name"), f"{where}name")
    out: list[StateWrite] = []
    if not any(item.get(f) is not None for f in _FIELDS):
        raise BadCommand(f"{where}position", f"nothing to write: give any of {_FIELDS}")
    if (p := item.get("position")) is not None:
        pos = _vector(p, 3, f"{where}position")
        outside = (pos < table.lower) | (pos > table.upper)
        if outside.any():
            axis = "xyz"[int(np.flatnonzero(outside)[0])]
            raise BadCommand(
                f"{where}position",
                f"{pos.tolist()} is outside the scene's bounds at {axis} ({table.bounds_text()})",
            )
        out.append(StateWrite("qpos", world, table.qpos[e] + np.arange(3), pos))
    if (q := item.get("orientation")) is not None:
        quat = _vector(q, 4, f"{where}orientation")
        norm = float(np.linalg.norm(quat))
        if abs(norm - 1.0) > QUAT_TOLERANCE:
            raise BadCommand(
                f"{where}orientation",
                f"quaternion norm {norm:.6g} is too far from 1 (|norm - 1| <= {QUAT_TOLERANCE})",
            )
        if abs(norm - 1.0) > _UNIT:
            quat = quat / norm
            notes.append(f"{where}orientation (norm {norm:.6g})")
        out.append(StateWrite("qpos", world, table.qpos[e] + 3 + np.arange(4), quat))
    for f, off, limit, unit in (
        ("linear", 0, MAX_LINEAR, "m/s"),
        ("angular", 3, MAX_ANGULAR, "rad/s"),
    ):
        if (v := item.get(f)) is not None:
            vec = _vector(v, 3, f"{where}{f}")
            speed = float(np.linalg.norm(vec))
            if speed > limit:
                raise BadCommand(
                    f"{where}{f}", f"|{f}| = {speed:.6g} {unit} exceeds {limit:g} {unit}"
                )
            out.append(StateWrite("qvel", world, table.qvel[e] + off + np.arange(3), vec))
    return out


@dataclass(frozen=True)
class SetEntities(ManyWrites[EntityResult], kind="set_entity", op="set_entity", http=("entities",)):
    """Poses and twists of entities in any worlds, written together at one tick boundary."""

    normalised: tuple[str, ...]  # the orientations normalised, by field

    @classmethod
    def create(cls, door: Door, items: Sequence[Mapping[str, Any]]) -> SetEntities:
        cls.counted(items, "entity")
        table = entity_table(door.loop.batch.robot.mjm)
        notes: list[str] = []
        writes: list[StateWrite] = []
        many = len(items) > 1
        for i, item in enumerate(items):
            writes += _checked(table, door.nworld, item, f"writes.{i}." if many else "", notes)
        kept = tuple({k: v for k, v in dict(it).items() if v is not None} for it in items)
        return cls(tuple(writes), kept, tuple(notes))

    def stage(self, door: Door, source: str) -> EntityResult:
        return EntityResult(*self.staged(door), list(self.normalised))

    def ack(self, door: Door, msg_id: Any, world: int, result: EntityResult) -> dict[str, Any]:
        return world_ack(msg_id, world, tick=result.tick, normalised=result.normalised)
