"""Seeded randomisation: `randomize` resets worlds to home and gives each its own entity poses
and physics parameters, drawn from ranges with a seed.

World w draws from `numpy.random.default_rng([seed, w])`, in the order the spec lists its
entries, so a world's draw depends only on the seed, its id and the spec: the same seed gives
the same worlds whichever worlds are named with it, on any engine, and a recording replays it
by drawing again (`from_record`). The draws are written as one reset plus the `set_entity` and
`set_params` writes of those values, at one tick boundary, so they are validated by the same
rules (a range reaching outside a limit is refused before anything is drawn).

spec = {
  "entities": {name: {"position": [[x0, x1], [y0, y1], [z0, z1]], "yaw": [a0, a1]}},
  "params": {name: [lo, hi]  (or one [lo, hi] per number: payload)},
}
Each entry is optional; "yaw" [rad] turns the entity about the world's z axis (upright), its
bounds within ±4π (two turns either way: any angle, and never a range too wide to draw from).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import Field

from service.core.commands.base import Announcement, Command, Door, world_ack
from service.core.commands.entities import SetEntities
from service.core.commands.fields import Strict, WorldId, example_config
from service.core.commands.params import SetParams, param_table
from service.core.errors import BadCommand
from service.core.sim import rules
from service.core.sim.entities import entity_table

__all__ = ["Randomize", "RandomizeAck", "RandomizeRequest"]

MAX_SEED = 2**63 - 1
MAX_YAW = 4 * math.pi  # [rad] |lo|, |hi| of a yaw range


class RandomizeRequest(Strict):
    seed: int = Field(ge=0, le=MAX_SEED, strict=True, description="same seed, same worlds")
    spec: dict[str, dict[str, Any]] = Field(
        description='{"entities": {name: {"position": [[lo, hi] x3], "yaw": [lo, hi]}}, '
        '"params": {name: [lo, hi]}}'
    )
    worlds: list[WorldId] | None = Field(default=None, description="omit for all worlds")

    model_config = example_config(
        {
            "seed": 42,
            "spec": {
                "entities": {
                    "cube": {
                        "position": [[0.6, 0.8], [0.0, 0.3], [0.78, 0.8]],
                        "yaw": [-3.14, 3.14],
                    }
                },
                "params": {"cube.mass": [0.05, 0.5]},
            },
        }
    )


class RandomizeAck(Strict):
    tick: int = Field(description="the first tick stepped from the drawn worlds")
    worlds: list[int]
    seed: int
    spec: dict[str, Any]


@dataclass(frozen=True)
class RandomizeResult:
    tick: int
    worlds: list[int]


def _range(value: Any, field: str) -> tuple[float, float]:
    ok = isinstance(value, list | tuple) and len(value) == 2
    if ok and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        lo, hi = float(value[0]), float(value[1])
        if math.isfinite(lo) and math.isfinite(hi) and lo <= hi:
            return lo, hi
    raise BadCommand(field, f"a range is [lo, hi] with finite lo <= hi, got {value!r}")


def _ranges(value: Any, n: int, field: str) -> list[tuple[float, float]]:
    if (
        n == 1
        and isinstance(value, list | tuple)
        and len(value) == 2
        and not any(isinstance(v, list | tuple) for v in value)
    ):
        return [_range(value, field)]
    if not isinstance(value, list | tuple) or len(value) != n:
        raise BadCommand(field, f"needs {n} ranges [lo, hi], got {value!r}")
    return [_range(v, f"{field}.{i}") for i, v in enumerate(value)]


@dataclass(frozen=True)
class Plan:
    """What to draw, in draw order: (entity, position ranges or None, yaw range or None) and
    (parameter, ranges)."""

    entities: tuple[tuple[str, tuple | None, tuple | None], ...]
    params: tuple[tuple[str, tuple], ...]


def plan(door: Door, spec: Any) -> Plan:
    """The spec checked against the scene (names, shapes, ranges inside the limits)."""
    if not isinstance(spec, Mapping) or set(spec) - {"entities", "params"}:
        raise BadCommand("spec", 'the spec is {"entities": {...}, "params": {...}}')
    mjm = door.loop.batch.robot.mjm
    table, params = entity_table(mjm), param_table(mjm, door.spec.names)
    ents = []
    for name, e in dict(spec.get("entities") or {}).items():
        where = f"spec.entities.{name}"
        table.index(name, where)
        if not isinstance(e, Mapping) or not e or set(e) - {"position", "yaw"}:
            raise BadCommand(where, 'give "position" ranges and/or a "yaw" range')
        pos = (
            None
            if e.get("position") is None
            else tuple(_ranges(e["position"], 3, f"{where}.position"))
        )
        if pos is not None:
            lo, hi = np.array([r[0] for r in pos]), np.array([r[1] for r in pos])
            if (lo < table.lower).any() or (hi > table.upper).any():
                raise BadCommand(
                    f"{where}.position",
                    f"reaches outside the scene's bounds ({table.bounds_text()})",
                )
        yaw = None if e.get("yaw") is None else _range(e["yaw"], f"{where}.yaw")
        if yaw is not None and max(abs(yaw[0]), abs(yaw[1])) > MAX_YAW:
            raise BadCommand(
                f"{where}.yaw", f"{list(yaw)} reaches outside ±4π rad (±{MAX_YAW:.6g})"
            )
        ents.append((name, pos, yaw))
    pars = []
    for name, value in dict(spec.get("params") or {}).items():
        where = f"spec.params.{name}"
        p = params.get(name)
        if p is None:
            raise BadCommand(where, f"unknown parameter; parameters are {list(params)}")
        ranges = tuple(_ranges(value, p.size, where))
        for (lo, hi), low, high in zip(ranges, p.lower, p.upper, strict=True):
            if lo < low or hi > high:
                raise BadCommand(
                    where, f"[{lo:g}, {hi:g}] reaches outside {low:g}..{high:g} {p.unit}"
                )
        pars.append((name, ranges))
    if not ents and not pars:
        raise BadCommand("spec", "nothing to randomise: name entities or params")
    return Plan(tuple(ents), tuple(pars))


def draw(p: Plan, seed: int, worlds: Sequence[int]) -> tuple[list[dict], list[dict]]:
    """Entity and parameter writes of every world, drawn world by world."""
    entity_items, param_items = [], []
    for w in worlds:
        rng = np.random.default_rng([seed, w])
        for name, pos, yaw in p.entities:
            item: dict[str, Any] = {
                "world": w,
                "name": name,
                "linear": [0.0] * 3,
                "angular": [0.0] * 3,
            }
            if pos is not None:
                item["position"] = [float(rng.uniform(lo, hi)) for lo, hi in pos]
            if yaw is not None:
                a = float(rng.uniform(*yaw))
                item["orientation"] = [math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)]
            entity_items.append(item)
        values = {}
        for name, ranges in p.params:
            drawn = [float(rng.uniform(lo, hi)) for lo, hi in ranges]
            values[name] = drawn[0] if len(drawn) == 1 else drawn
        if values:
            param_items.append({"world": w, "params": values})
    return entity_items, param_items


@dataclass(frozen=True)
class Randomize(Command[RandomizeResult], kind="randomize", op="randomize", http=("randomize",)):
    """Reset worlds to home with entity poses and parameters drawn from `spec` with `seed`."""

    worlds: list[int]
    seed: int
    spec: dict[str, Any]
    entities: SetEntities | None
    params: SetParams | None

    @classmethod
    def create(cls, door: Door, worlds: Sequence[object] | None, seed: Any, spec: Any) -> Randomize:
        ids = list(range(door.nworld)) if worlds is None else rules.world_ids(worlds, door.nworld)
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
            raise BadCommand("seed", f"a seed is an integer in 0..2^63-1, got {seed!r}")
        entity_items, param_items = draw(plan(door, spec), seed, ids)
        ents = SetEntities.create(door, entity_items) if entity_items else None
        pars = SetParams.create(door, param_items) if param_items else None
        return cls(ids, seed, dict(spec), ents, pars)

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> Randomize:
        extra = set(body) - {"seed", "spec"}
        if extra:
            raise BadCommand(sorted(extra)[0], "randomize takes seed and spec")
        return cls.create(door, [world], body.get("seed"), body.get("spec"))

    def stage(self, door: Door, source: str) -> RandomizeResult:
        writes = [
            *(self.params.writes if self.params else ()),
            *(self.entities.writes if self.entities else ()),
        ]
        # one boundary for the reset and the draws; the loop notes seed and spec with its tick
        tick = door.loop.commands.reset(self.worlds, writes, (self.seed, self.spec))
        return RandomizeResult(tick, self.worlds)

    def announce(self, door: Door, result: RandomizeResult) -> Announcement:
        worlds = np.array(result.worlds, dtype=np.int64)
        targets = np.tile(door.loop.batch.home_target, (len(worlds), 1))
        return Announcement(worlds, targets, result.tick, {"seed": self.seed, "spec": self.spec})

    def ack(self, door: Door, msg_id: Any, world: int, result: RandomizeResult) -> dict[str, Any]:
        return world_ack(msg_id, world, tick=result.tick, seed=self.seed, spec=self.spec)

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> Randomize:
        return cls.create(door, rec["worlds"], rec["seed"], rec["spec"])
