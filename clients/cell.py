"""Entities and per-world physics parameters: the calls the clients make (no I/O here).

An entity is a named free body of the scene, in every world: its pose (`position` x y z [m],
`orientation` w x y z) and twist (`linear` [m/s], world frame; `angular` [rad/s], body frame).
A parameter is one of the names `GET /v1/params` lists (e.g. "cube.mass", "payload",
"elbow_joint.damping"). Replies are the service's JSON, as dicts; every write's reply has the
`tick` from which it is in effect.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from clients.calls import Call

Vector = Sequence[float]


def _identity(d: Any) -> Any:
    return d


def entity_values(
    position: Vector | None = None,
    orientation: Vector | None = None,
    linear: Vector | None = None,
    angular: Vector | None = None,
) -> dict[str, list[float]]:
    """The given parts of a pose and twist as a request body (None: left as it is)."""
    given = {"position": position, "orientation": orientation}
    given |= {"linear": linear, "angular": angular}
    body = {k: [float(x) for x in v] for k, v in given.items() if v is not None}
    if not body:
        raise ValueError("give any of position, orientation, linear, angular")
    return body


def entities_call(world: int) -> Call:
    return Call("GET", f"/v1/worlds/{int(world)}/entities", _identity)


def entity_call(world: int, name: str) -> Call:
    return Call("GET", f"/v1/worlds/{int(world)}/entities/{name}", _identity)


def set_entity_call(world: int, name: str, **values: Vector | None) -> Call:
    path = f"/v1/worlds/{int(world)}/entities/{name}"
    return Call("PUT", path, _identity, json=entity_values(**values))


def set_entities_call(writes: Iterable[Mapping[str, Any]]) -> Call:
    """Writes `{"world": w, "name": n, "position": [...], ...}` applied at one tick."""
    body = [{"world": int(w["world"]), "name": str(w["name"]), **entity_values(
        w.get("position"), w.get("orientation"), w.get("linear"), w.get("angular"))}
        for w in writes]  # fmt: skip
    return Call("POST", "/v1/entities", _identity, json={"writes": body})


def param_table_call() -> Call:
    return Call("GET", "/v1/params", _identity)


def params_call(world: int) -> Call:
    return Call("GET", f"/v1/worlds/{int(world)}/params", _identity)


def _values(params: Mapping[str, Any]) -> dict[str, Any]:
    if not params:
        raise ValueError("give at least one parameter")
    return {
        str(k): [float(x) for x in v] if isinstance(v, list | tuple) else float(v)
        for k, v in params.items()
    }


def set_params_call(world: int, params: Mapping[str, Any]) -> Call:
    path = f"/v1/worlds/{int(world)}/params"
    return Call("PUT", path, _identity, json={"params": _values(params)})


def set_params_many_call(writes: Iterable[tuple[int, Mapping[str, Any]]]) -> Call:
    """(world, params) pairs applied at one tick."""
    body = [{"world": int(w), "params": _values(p)} for w, p in writes]
    return Call("POST", "/v1/params", _identity, json={"writes": body})


def randomize_call(seed: int, spec: Mapping[str, Any], worlds: Iterable[int] | None = None) -> Call:
    """Worlds (None: all) reset with entity poses and parameters drawn from `spec` with `seed`."""
    body: dict[str, Any] = {"seed": int(seed), "spec": dict(spec)}
    if worlds is not None:
        body["worlds"] = [int(w) for w in worlds]
    return Call("POST", "/v1/randomize", _identity, json=body)


def randomization_call(world: int) -> Call:
    return Call("GET", f"/v1/worlds/{int(world)}/randomization", _identity)
