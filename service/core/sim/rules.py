"""The rules every command obeys, each written once and applied once, at construction.

- `world_id` / `world_ids`: a world is an integer in 0..nworld-1 (404 naming every unknown one).
- `joint_state`: a sensor_msgs/JointState-shaped command (`name`, `position`): the same answer
  on every surface (HTTP, WebSocket, the page, rosbridge, Foxglove, the ROS node). Names and
  positions pair up (a subset moves only those joints); with no names, one position per joint
  in joint order, as the seed's Isaac subscriber read them; every name a joint's name or its
  index as a digit string, no joint named twice (neither by the same name nor by its name and
  its index); every position a finite number.
- Clamping to the joint ranges happens when a target is staged (`arithmetic`), once; the loop
  and the engines trust what was staged.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from service.core.errors import BadCommand, UnknownWorld
from service.core.sim.types import RobotSpec


def _is_id(w: object) -> bool:
    return not isinstance(w, bool) and isinstance(w, int | np.integer)


def world_id(world: object, nworld: int, field: str = "world") -> int:
    """A world id as an int, or UnknownWorld / BadCommand naming what is wrong."""
    if not _is_id(world):
        raise BadCommand(field, f"a world id must be an integer, got {world!r}")
    if not 0 <= world < nworld:  # type: ignore[operator]
        raise UnknownWorld(int(world), nworld)  # type: ignore[call-overload]
    return int(world)  # type: ignore[call-overload]


def world_ids(worlds: Sequence[object], nworld: int, field: str = "worlds") -> list[int]:
    """Several world ids; every unknown one is named in one 404."""
    for w in worlds:
        if not _is_id(w):
            raise BadCommand(field, f"world ids must be integers, got {w!r}")
    missing = [int(w) for w in worlds if not 0 <= w < nworld]  # type: ignore[operator,call-overload]
    if missing:
        raise UnknownWorld(missing, nworld)
    return [int(w) for w in worlds]  # type: ignore[call-overload]


class BadJointState(BadCommand):
    """A JointState-shaped command broke the rule; `reason` classifies it for the surfaces that
    count refusals by kind (empty, length_mismatch, unknown_joint, duplicate_joint, bad_type,
    not_finite)."""

    def __init__(self, reason: str, field: str, message: str) -> None:
        super().__init__(field, message)
        self.reason = reason


def joint_state(spec: RobotSpec, name: Any, position: Any) -> dict[int, float]:
    """A JointState command's (`name`, `position`) → {joint index: target}; BadJointState
    naming the field otherwise. Velocity and effort are not commands; callers ignore them."""
    for field, value in (("name", name), ("position", position)):
        if not isinstance(value, list | tuple):
            raise BadJointState("bad_type", field, f"{field} must be an array, got {value!r}")
    if len(position) == 0:
        raise BadJointState("empty", "position", "position is empty; nothing to command")
    joints = spec.names
    if len(name) == 0:
        if len(position) != len(joints):
            raise BadJointState(
                "length_mismatch",
                "position",
                f"without names, position needs all {len(joints)} joints (got {len(position)})",
            )
        name = joints
    elif len(name) != len(position):
        raise BadJointState(
            "length_mismatch",
            "position",
            f"name and position must have equal lengths ({len(name)} names, "
            f"{len(position)} positions)",
        )
    out: dict[int, float] = {}
    for n, p in zip(name, position, strict=True):
        if not isinstance(n, str):
            raise BadJointState("bad_type", "name", f"a joint is named by a string, got {n!r}")
        try:  # a joint name, or its index as a string (how JSON object keys name joints)
            index = spec.index(int(n) if isinstance(n, str) and n.isdigit() else n)
        except (KeyError, TypeError):
            why = f"unknown joint {n!r}; joints are {joints}"
            raise BadJointState("unknown_joint", "name", why) from None
        if index in out:  # the same name twice, or a name and that joint's index
            why = f"joint {spec.names[index]!r} named twice"
            raise BadJointState("duplicate_joint", "name", why)
        if isinstance(p, bool) or not isinstance(p, int | float):
            raise BadJointState("bad_type", f"position.{n}", f"must be a number, got {p!r}")
        if not math.isfinite(p):
            raise BadJointState("not_finite", f"position.{n}", f"{p} is not finite (no NaN or Inf)")
        out[index] = float(p)
    return out
