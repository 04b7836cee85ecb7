"""Per-world physics parameters: the declared table of what may differ between worlds, and
`set_params`, which gives worlds their own values at one tick boundary.

The table (`param_table`, read from the model) names every parameter, its unit, its range and
the MjModel entries it edits; a value is written as `ModelWrite`s (service.core.sim.batch), which
every engine applies per world (MuJoCo Warp batches only the fields some world changed;
native MuJoCo expands them per world). The entries are edited as one would edit an `MjModel`
by hand, and nothing else: what `mj_setConst` derives from them (`body_invweight0`, ...) keeps
the scene's values, so a world steps exactly as `mujoco.mj_step` on a model edited alike.

| parameter            | unit        | range      | edits                                      |
|----------------------|-------------|------------|--------------------------------------------|
| `<entity>.mass`      | kg          | 0.001..100 | body_mass; body_inertia scaled alike       |
| `<entity>.friction`  | 1           | 0..5       | geom_friction[:, 0] of the body's geoms    |
| `payload`            | kg, m, m, m | see below  | the flange body's mass, ipos, inertia, iquat|
| `<arm joint>.damping`| N·m·s/rad   | 0..1000    | dof_damping                                |
| `<arm joint>.armature`| kg·m²      | 0..10      | dof_armature                               |
| `<joint>.kp`         | N·m/rad     | 0..100000  | actuator_gainprm[0], actuator_biasprm[1]   |
| `<joint>.kv`         | N·m·s/rad   | 0..10000   | actuator_biasprm[2]                        |

`payload` is [mass, x, y, z]: a point mass 0..12.5 kg at x y z (each within ±0.3 m) in the
flange frame, added to the body that carries the flange (mass, centre and inertia combined by
the parallel-axis rule); mass 0 puts that body back as the scene has it. Values are kept
through resets (they describe the world, not its state).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from pydantic import Field

from service.core.commands.base import Door, world_ack
from service.core.commands.fields import FiniteFloat, Strict, WorldId, example_config
from service.core.commands.writes import MAX_WRITES, ManyWrites, batch_config
from service.core.errors import BadCommand
from service.core.sim import rules
from service.core.sim.batch import Batch, ModelWrite
from service.core.sim.entities import entity_table
from service.core.sim.robot import FLANGE_SITE

__all__ = ["Param", "SetParams", "param_table", "read"]

PAYLOAD_MASS = 12.5  # kg, the UR10e's rated payload
PAYLOAD_REACH = 0.3  # m, |x|, |y|, |z| of the payload's centre from the flange

Edit = tuple[str, tuple[int, ...], float]  # (MjModel field, entry, value)


@dataclass(frozen=True)
class Param:
    """One parameter: `size` numbers each in lower..upper [unit]; `edits(values)` the model
    entries they set; `read(field -> one world's row)` its value back."""

    name: str
    unit: str
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    edits: Callable[[np.ndarray], list[Edit]]
    read: Callable[[Mapping[str, np.ndarray]], list[float]]
    fields: tuple[str, ...]

    @property
    def size(self) -> int:
        return len(self.lower)

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "unit": self.unit, "lower": self.lower, "upper": self.upper}


def _scalar(
    name: str,
    unit: str,
    lo: float,
    hi: float,
    field: str,
    entries: list[tuple[int, ...]],
    scale: float = 1.0,
) -> Param:
    """A number written to `entries` of `field` (times `scale`), read from the first."""
    first = entries[0]
    return Param(
        name,
        unit,
        (lo,),
        (hi,),
        lambda v: [(field, e, scale * float(v[0])) for e in entries],
        lambda rows: [float(rows[field][first]) / scale],
        (field,),
    )


def _mass(name: str, mjm: mujoco.MjModel, body: int) -> Param:
    m0, i0 = float(mjm.body_mass[body]), mjm.body_inertia[body].copy()

    def edits(v: np.ndarray) -> list[Edit]:
        scaled = [("body_inertia", (body, k), float(i0[k] * v[0] / m0)) for k in range(3)]
        return [("body_mass", (body,), float(v[0])), *scaled]

    return Param(
        name,
        "kg",
        (0.001,),
        (100.0,),
        edits,
        lambda rows: [float(rows["body_mass"][body])],
        ("body_mass", "body_inertia"),
    )


def combined_inertia(
    m0: float, p0: np.ndarray, iquat0: np.ndarray, i0: np.ndarray, mp: float, c: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """A body (mass m0, centre p0, principal inertia i0 in frame iquat0) plus a point mass mp
    at c, both in the body frame: (mass, centre, principal inertia, its frame's quaternion)."""
    if mp == 0.0:
        return m0, p0.copy(), i0.copy(), iquat0.copy()
    mass = m0 + mp
    centre = (m0 * p0 + mp * c) / mass
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, iquat0)
    rot = rot.reshape(3, 3)
    tensor = rot @ np.diag(i0) @ rot.T
    for m, p in ((m0, p0), (mp, c)):
        d = p - centre
        tensor += m * (d @ d * np.eye(3) - np.outer(d, d))
    values, vectors = np.linalg.eigh(tensor)
    if np.linalg.det(vectors) < 0:
        vectors[:, 0] = -vectors[:, 0]
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, vectors.ravel())
    return mass, centre, values, quat


def _payload(mjm: mujoco.MjModel) -> Param:
    site = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_SITE, FLANGE_SITE)
    body = int(mjm.site_bodyid[site])
    m0, p0 = float(mjm.body_mass[body]), mjm.body_ipos[body].copy()
    q0, i0 = mjm.body_iquat[body].copy(), mjm.body_inertia[body].copy()
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, mjm.site_quat[site])
    site_pos, site_rot = mjm.site_pos[site].copy(), rot.reshape(3, 3)

    def edits(v: np.ndarray) -> list[Edit]:
        c = site_pos + site_rot @ v[1:]
        mass, centre, inertia, quat = combined_inertia(m0, p0, q0, i0, float(v[0]), c)
        out: list[Edit] = [("body_mass", (body,), mass)]
        out += [("body_ipos", (body, k), float(centre[k])) for k in range(3)]
        out += [("body_inertia", (body, k), float(inertia[k])) for k in range(3)]
        return out + [("body_iquat", (body, k), float(quat[k])) for k in range(4)]

    def read_back(rows: Mapping[str, np.ndarray]) -> list[float]:
        mp = float(rows["body_mass"][body]) - m0
        if mp <= 0.0:
            return [0.0, 0.0, 0.0, 0.0]
        c = (m0 + mp) * rows["body_ipos"][body] - m0 * p0
        return [mp, *(site_rot.T @ (c / mp - site_pos)).tolist()]

    r = PAYLOAD_REACH
    return Param(
        "payload",
        "kg, m, m, m",
        (0.0, -r, -r, -r),
        (PAYLOAD_MASS, r, r, r),
        edits,
        read_back,
        ("body_mass", "body_ipos", "body_inertia", "body_iquat"),
    )


# Per model object, for as long as it lives (see entities._TABLES).
_TABLES: weakref.WeakKeyDictionary[mujoco.MjModel, dict[str, Param]] = weakref.WeakKeyDictionary()


def param_table(mjm: mujoco.MjModel, commanded: Sequence[str]) -> dict[str, Param]:
    """Every parameter of a compiled model by name (built once per model object);
    `commanded`: the commanded joints (the last is the gripper's, without damping/armature)."""
    table = _TABLES.get(mjm)
    if table is not None:
        return table
    params: list[Param] = []
    entities = entity_table(mjm)
    for name, body in zip(entities.names, entities.body.tolist(), strict=True):
        geoms = [(g, 0) for g in range(mjm.ngeom) if mjm.geom_bodyid[g] == body]
        params.append(_mass(f"{name}.mass", mjm, body))
        if geoms:
            params.append(_scalar(f"{name}.friction", "1", 0.0, 5.0, "geom_friction", geoms))
    params.append(_payload(mjm))
    for i, joint in enumerate(commanded):
        jid = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, joint)
        dof = int(mjm.jnt_dofadr[jid])
        if i < len(commanded) - 1:
            params.append(
                _scalar(f"{joint}.damping", "N·m·s/rad", 0, 1000, "dof_damping", [(dof,)])
            )
            params.append(_scalar(f"{joint}.armature", "kg·m²", 0, 10, "dof_armature", [(dof,)]))
        act = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_ACTUATOR, joint)
        kp = _scalar(f"{joint}.kp", "N·m/rad", 0, 1e5, "actuator_gainprm", [(act, 0)])
        bias = _scalar(f"{joint}.kp", "", 0, 1e5, "actuator_biasprm", [(act, 1)], -1.0)
        params.append(
            Param(
                kp.name,
                kp.unit,
                kp.lower,
                kp.upper,
                lambda v, kp=kp, bias=bias: kp.edits(v) + bias.edits(v),
                kp.read,
                ("actuator_gainprm", "actuator_biasprm"),
            )
        )
        params.append(
            _scalar(f"{joint}.kv", "N·m·s/rad", 0, 1e4, "actuator_biasprm", [(act, 2)], -1.0)
        )
    table = _TABLES[mjm] = {p.name: p for p in params}
    return table


def _table(batch: Batch) -> dict[str, Param]:
    return param_table(batch.robot.mjm, batch.spec.names)


# -- the wire form ------------------------------------------------------------------------


class ParamValues(Strict):
    params: dict[str, FiniteFloat | list[FiniteFloat]] = Field(
        min_length=1, description="parameter name → value ([mass, x, y, z] for payload)"
    )

    model_config = example_config(
        {"params": {"cube.mass": 0.3, "cube.friction": 0.5, "payload": [1.5, 0, 0, 0.08]}}
    )


class ParamWrite(ParamValues):
    world: WorldId

    model_config = example_config({"world": 0, "params": {"cube.mass": 0.3}})


class ParamWrites(Strict):
    writes: list[ParamWrite] = Field(min_length=1, max_length=MAX_WRITES)

    model_config = batch_config(
        {"world": 0, "params": {"cube.mass": 0.3}},
        {"world": 1, "params": {"elbow_joint.damping": 5}},
    )


class ParamsAck(Strict):
    tick: int = Field(description="the first tick stepped with the new values")
    worlds: list[int]


@dataclass(frozen=True)
class ParamsResult:
    tick: int
    worlds: list[int]


def _values(param: Param, value: Any, field: str) -> np.ndarray:
    given = value if isinstance(value, list | tuple) else [value]
    if len(given) != param.size or any(
        isinstance(v, bool) or not isinstance(v, int | float) for v in given
    ):
        shape = "a number" if param.size == 1 else f"a list of {param.size} numbers"
        raise BadCommand(field, f"must be {shape} ({param.unit}), got {value!r}")
    for v, lo, hi in zip(given, param.lower, param.upper, strict=True):
        if not math.isfinite(v):
            raise BadCommand(field, f"{v} is not finite (no NaN or Inf)")
        if not lo <= v <= hi:
            raise BadCommand(field, f"{v} is outside {lo:g}..{hi:g} {param.unit}")
    return np.array(given, dtype=np.float64)


def _writes(mjm: mujoco.MjModel, world: int, edits: list[Edit]) -> list[ModelWrite]:
    """Edits of one world as one ModelWrite per field."""
    by_field: dict[str, tuple[list[int], list[float]]] = {}
    for field, entry, value in edits:
        index, values = by_field.setdefault(field, ([], []))
        index.append(int(np.ravel_multi_index(entry, getattr(mjm, field).shape)))
        values.append(value)
    return [
        ModelWrite(f, world, np.array(i, dtype=np.int64), np.array(v, dtype=np.float64))
        for f, (i, v) in by_field.items()
    ]


@dataclass(frozen=True)
class SetParams(ManyWrites[ParamsResult], kind="set_params", op="set_params", http=("params",)):
    """Per-world physics parameters of any worlds, written together at one tick boundary."""

    @classmethod
    def create(cls, door: Door, items: Sequence[Mapping[str, Any]]) -> SetParams:
        cls.counted(items, "parameter")
        batch = door.loop.batch
        table, mjm = _table(batch), batch.robot.mjm
        out: list[ModelWrite] = []
        many = len(items) > 1
        for i, item in enumerate(items):
            where = f"writes.{i}." if many else ""
            if not isinstance(item, Mapping) or set(item) - {"world", "params"}:
                raise BadCommand(where or "writes", "a write is {world, params}")
            world = rules.world_id(item.get("world"), door.nworld, f"{where}world")
            params = item.get("params")
            if not isinstance(params, Mapping) or not params:
                raise BadCommand(f"{where}params", "give at least one parameter by name")
            for name, value in params.items():
                param = table.get(name)
                if param is None:
                    raise BadCommand(
                        f"{where}params",
                        f"unknown parameter {name!r}; parameters are {list(table)}",
                    )
                values = _values(param, value, f"{where}params.{name}")
                out += _writes(mjm, world, param.edits(values))
        kept = tuple({"world": it["world"], "params": dict(it["params"])} for it in items)
        return cls(tuple(out), kept)

    def stage(self, door: Door, source: str) -> ParamsResult:
        return ParamsResult(*self.staged(door))

    def ack(self, door: Door, msg_id: Any, world: int, result: ParamsResult) -> dict[str, Any]:
        return world_ack(msg_id, world, tick=result.tick)


def read(batch: Batch, worlds: Sequence[int]) -> dict[str, Any]:
    """Every parameter of `worlds` as the engine holds it (call on the sim thread)."""
    table = _table(batch)
    fields = {f for p in table.values() for f in p.fields}
    values = {f: batch.model_values(f) for f in fields}
    rows = []
    for w in worlds:
        mine = {f: v[w] for f, v in values.items()}
        params = {n: (p.read(mine) if p.size > 1 else p.read(mine)[0]) for n, p in table.items()}
        rows.append({"world": int(w), "params": params})
    return {"tick": batch.tick, "worlds": rows}
