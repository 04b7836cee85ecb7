"""The served cell in the OpenAPI document: what JSON Schema can say about its names and limits.

The request models (service/core/commands) are written once for any cell, so pydantic alone
would describe an entity name as any string, a parameter table as any object and a
randomisation spec as any dict: schema-valid bodies the server then refuses. `fit_cell`
rewrites those parts of the generated document from the model being served: its entity and
parameter names as enums and closed objects, the scene's bounds, each parameter's range and
shape, and a spec's exact layout. What JSON Schema cannot say stays in the field's description
and is refused with 422 naming the field and the limit: a quaternion's norm, a velocity's
norm, a range's `lo <= hi` (one number against another).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco

from service.core.commands.entities import MAX_ANGULAR, MAX_LINEAR, QUAT_TOLERANCE
from service.core.commands.params import Param, param_table
from service.core.commands.randomize import MAX_SEED, MAX_YAW
from service.core.sim.entities import EntityTable, entity_table

__all__ = ["fit_cell"]

# Paths whose `{name}` is an entity of the served cell (an unknown one answers 404).
ENTITY_PATHS = ("/v1/worlds/{world}/entities/{name}",)
_ENTITY_FIELDS = ("position", "orientation", "linear", "angular")


def _number(lo: float, hi: float) -> dict[str, Any]:
    return {"type": "number", "minimum": lo, "maximum": hi}


def _tuple(items: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """An array of exactly these items, each with its own schema."""
    n = len(items)
    return {"type": "array", "minItems": n, "maxItems": n, "prefixItems": list(items)}


def _nullable(schema: dict[str, Any], description: str) -> dict[str, Any]:
    """`X | None` as pydantic writes it (the server takes null as absent)."""
    return {"anyOf": [schema, {"type": "null"}], "description": description}


def _range(lo: float, hi: float) -> dict[str, Any]:
    """A [lo, hi] pair inside lo..hi (that the first is not above the second, it cannot say)."""
    return {"type": "array", "minItems": 2, "maxItems": 2, "items": _number(lo, hi)}


# -- entities -----------------------------------------------------------------------------


def _entity_fields(table: EntityTable) -> dict[str, dict[str, Any]]:
    bounds = zip(table.lower.tolist(), table.upper.tolist(), strict=True)
    position = _tuple([_number(lo, hi) for lo, hi in bounds])
    q, v, w = 1 + QUAT_TOLERANCE, MAX_LINEAR, MAX_ANGULAR
    return {
        "position": _nullable(
            position, f"x y z [m], world frame, inside the scene's bounds ({table.bounds_text()})"
        ),
        "orientation": _nullable(
            _tuple([_number(-q, q)] * 4),
            f"quaternion w x y z whose norm is within 1 ± {QUAT_TOLERANCE:g} (normalised when "
            "it is not 1; JSON Schema cannot state a norm: any other is refused with 422)",
        ),
        "linear": _nullable(
            _tuple([_number(-v, v)] * 3),
            f"linear velocity [m/s], world frame; |linear| <= {v:g} m/s (a norm: JSON Schema "
            "cannot state it, a faster one is refused with 422)",
        ),
        "angular": _nullable(
            _tuple([_number(-w, w)] * 3),
            f"angular velocity [rad/s], body frame; |angular| <= {w:g} rad/s (a norm: JSON "
            "Schema cannot state it, a faster one is refused with 422)",
        ),
    }


def _at_least_one(fields: Sequence[str]) -> list[dict[str, Any]]:
    """anyOf branches: at least one of `fields` given, and not null."""
    return [{"required": [f], "properties": {f: {"type": "array"}}} for f in fields]


def _fit_entities(schemas: dict[str, Any], paths: dict[str, Any], table: EntityTable) -> None:
    names = {"type": "string", "enum": list(table.names), "description": "an entity of the cell"}
    for key in ("EntityValues", "EntityWrite"):
        model = schemas.get(key)
        if model is None:
            continue
        model["properties"].update(_entity_fields(table))
        model["anyOf"] = _at_least_one(_ENTITY_FIELDS)
        if "name" in model["properties"]:
            model["properties"]["name"] = {**names, "title": "Name"}
    for path in ENTITY_PATHS:
        for op in paths.get(path, {}).values():
            for param in op.get("parameters", []):
                if param["in"] == "path" and param["name"] == "name":
                    param["schema"] = {**names, "title": "Name"}


# -- parameters and randomisation -----------------------------------------------------------


def _value(p: Param) -> dict[str, Any]:
    """A parameter's value: a number in its range (or a list of that one number), or a list of
    `size` numbers each in its own range."""
    numbers = [_number(lo, hi) for lo, hi in zip(p.lower, p.upper, strict=True)]
    ranges = ", ".join(f"{lo:g}..{hi:g}" for lo, hi in zip(p.lower, p.upper, strict=True))
    about = f"{p.unit}: {ranges}"
    if p.size == 1:
        return {"anyOf": [numbers[0], _tuple(numbers)], "description": about}
    return {**_tuple(numbers), "description": about}


def _ranges(p: Param) -> dict[str, Any]:
    """A parameter's randomisation: [lo, hi] inside its range (one per number when several)."""
    pairs = [_range(lo, hi) for lo, hi in zip(p.lower, p.upper, strict=True)]
    about = f"[lo, hi] with lo <= hi, inside the parameter's range ({p.unit})"
    if p.size == 1:
        return {"anyOf": [pairs[0], _tuple(pairs)], "description": about}
    return {**_tuple(pairs), "description": f"{p.size} of {about}"}


def _closed(properties: dict[str, Any], description: str, least: int = 0) -> dict[str, Any]:
    out: dict[str, Any] = {
        "type": "object",
        "properties": properties,
        "additionalProperties": False,
        "description": description,
    }
    if least:
        out["minProperties"] = least
    return out


def _spec(table: EntityTable, params: dict[str, Param]) -> dict[str, Any]:
    axes = [
        _range(lo, hi) for lo, hi in zip(table.lower.tolist(), table.upper.tolist(), strict=True)
    ]
    entity = _closed(
        {
            "position": _nullable(_tuple(axes), "[lo, hi] per axis x y z [m], lo <= hi"),
            "yaw": _nullable(_range(-MAX_YAW, MAX_YAW), "[lo, hi] [rad] about z, lo <= hi"),
        },
        "what to draw of the entity (at least one)",
        least=1,
    )
    entities = _closed({n: entity for n in table.names}, "entity name → its ranges")
    ranges = _closed({n: _ranges(p) for n, p in params.items()}, "parameter name → its range")
    spec = _closed(
        {"entities": entities, "params": ranges},
        "what to draw (at least one entity or parameter); a range [lo, hi] needs lo <= hi, "
        "which JSON Schema cannot state (the server refuses it with 422)",
    )
    spec["anyOf"] = [
        {"required": [key], "properties": {key: {"minProperties": 1}}}
        for key in ("entities", "params")
    ]
    return spec


def _fit_params(schemas: dict[str, Any], table: EntityTable, params: dict[str, Param]) -> None:
    values = _closed(
        {n: _value(p) for n, p in params.items()},
        "parameter name → value (GET /v1/params lists names, units and ranges)",
        least=1,
    )
    for key in ("ParamValues", "ParamWrite"):
        if key in schemas:
            schemas[key]["properties"]["params"] = {**values, "title": "Params"}
    randomize = schemas.get("RandomizeRequest")
    if randomize is not None:
        randomize["properties"]["spec"] = {**_spec(table, params), "title": "Spec"}
        # FastAPI writes bounds as floats: 2**63 - 1 became 2**63, a seed the server refuses
        randomize["properties"]["seed"]["maximum"] = MAX_SEED


def fit_cell(spec: dict[str, Any], mjm: mujoco.MjModel, commanded: Sequence[str]) -> dict[str, Any]:
    """The document with the served cell's names and limits (`mjm`: its compiled model,
    `commanded`: the commanded joints, as `param_table` takes them)."""
    schemas = spec.get("components", {}).get("schemas", {})
    table = entity_table(mjm)
    _fit_entities(schemas, spec.get("paths", {}), table)
    _fit_params(schemas, table, param_table(mjm, commanded))
    return spec
