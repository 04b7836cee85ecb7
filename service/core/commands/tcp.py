"""`set_tcp`: a world's TCP offset from the flange, as a UR program sets it (URScript
`set_tcp(p[x, y, z, rx, ry, rz])`, ur_rtde `setTcp(pose)`).

Every Cartesian command and pose read of the world uses it from then on (the table is
service.core.kinematics.tools). It moves nothing: the arm's targets stay as they are.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import Field

from service.core.commands.base import Announcement, Command, Door, world_ack
from service.core.commands.fields import FiniteFloat, Strict, example_config
from service.core.errors import BadCommand
from service.core.kinematics.tools import tools_of
from service.core.sim import rules

__all__ = ["POSE_REACH", "TCP_REACH", "SetTcp", "TcpOffset", "pose_field", "pose_values"]

TCP_REACH = 1.0  # m: |x|, |y|, |z| of a TCP offset from the flange
POSE_REACH = 3.0  # m: |x|, |y|, |z| of a pose in the base frame (the UR10e reaches 1.3 m)
ROT_REACH = 2 * math.pi  # rad: |rx|, |ry|, |rz| of a rotation vector


def pose_field(reach: float, what: str, example: list[float]) -> Any:
    """A UR pose field p[x, y, z, rx, ry, rz]: position within ±reach m, rotation vector
    components within ±2π rad (the schema states both)."""
    return Field(
        min_length=6,
        max_length=6,
        description=f"{what}: x y z [m] (each within ±{reach:g}) and a rotation vector "
        f"rx ry rz [rad] (each within ±2π), as UR's p[...]",
        json_schema_extra={
            "prefixItems": [{"type": "number", "minimum": -reach, "maximum": reach}] * 3
            + [{"type": "number", "minimum": -ROT_REACH, "maximum": ROT_REACH}] * 3,
            "examples": [example],
        },
    )


def pose_values(value: Any, field: str, reach: float) -> np.ndarray:
    """Six finite numbers, x y z within ±reach [m] and rx ry rz within ±2π [rad]; BadCommand
    naming the element and the limit otherwise."""
    if not isinstance(value, list | tuple) or len(value) != 6:
        raise BadCommand(field, f"must be 6 numbers p[x, y, z, rx, ry, rz], got {value!r}")
    out = np.empty(6)
    for i, v in enumerate(value):
        limit, unit = (reach, "m") if i < 3 else (ROT_REACH, "rad")
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise BadCommand(f"{field}[{i}]", f"must be a finite number ({unit}), got {v!r}")
        if abs(v) > limit:
            raise BadCommand(f"{field}[{i}]", f"{v} is outside ±{limit:g} {unit}")
        out[i] = float(v)
    return out


_TCP_FIELD = pose_field(TCP_REACH, "offset from the flange, flange frame", [0, 0, 0.2, 0, 0, 0])


class TcpOffset(Strict):
    """A world's TCP: where the tool's centre point is in the flange frame."""

    tcp: list[FiniteFloat] = _TCP_FIELD

    model_config = example_config({"tcp": [0, 0, 0.2, 0, 0, 0]})


@dataclass(frozen=True)
class TcpSet:
    tick: int
    world: int
    tcp: list[float]


@dataclass(frozen=True)
class SetTcp(Command[TcpSet], kind="set_tcp", op="set_tcp", http=("tcp_offset",)):
    """Give one world its TCP offset (6,) from the flange."""

    world: int
    tcp: tuple[float, ...]

    @property
    def touches(self) -> Sequence[int]:
        return (self.world,)

    @classmethod
    def create(cls, door: Door, world: object, tcp: Any) -> SetTcp:
        world = rules.world_id(world, door.nworld)
        return cls(world, tuple(pose_values(tcp, "tcp", TCP_REACH).tolist()))

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> SetTcp:
        if set(body) != {"tcp"}:
            raise BadCommand("tcp", "set_tcp takes `tcp`: p[x, y, z, rx, ry, rz] and nothing else")
        return cls.create(door, world, body["tcp"])

    def stage(self, door: Door, source: str) -> TcpSet:
        tools_of(door.loop).set([self.world], np.array([self.tcp]))
        return TcpSet(door.loop.tick + 1, self.world, list(self.tcp))

    def announce(self, door: Door, result: TcpSet) -> Announcement:
        worlds = np.array([self.world], dtype=np.int64)
        targets = door.loop.commands.pending_targets(worlds)
        return Announcement(worlds, targets, result.tick, {"tcp": list(self.tcp)})

    def ack(self, door: Door, msg_id: Any, world: int, result: TcpSet) -> dict[str, Any]:
        return world_ack(msg_id, world, tick=result.tick, tcp=result.tcp)

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> SetTcp:
        return cls.create(door, rec["worlds"][0], rec["tcp"])
