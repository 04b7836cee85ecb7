"""The rules every command obeys, each written once and applied once, at construction.

- `world_id` / `world_ids`: a world is an integer in 0..nworld-1 (404 naming every unknown one).
- `joint_state`: a sensor_msgs/JointState-shaped command (`name`, `position`): the same answer
  on every surface (HTTP, WebSocket, the page, rosbridge, Foxglove, the ROS node). The rule is
  written once in the ROS rulebook (clients/ros_rules.py, which the ROS node imports too);
  here it becomes a 422 naming the field.
- Clamping to the joint ranges happens when a target is staged (`arithmetic`), once; the loop
  and the engines trust what was staged.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from clients import ros_rules
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
    naming the field otherwise. The rule itself is the ROS rulebook's (clients/ros_rules.py),
    which the ROS node applies too, so every face answers a bad message in the same words."""
    try:
        return ros_rules.joint_state(spec.names, name, position)
    except ros_rules.BadJointState as exc:
        raise BadJointState(exc.kind, exc.field, exc.message) from None
