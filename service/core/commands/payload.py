"""`set_payload`: the mass a world's arm carries and where its centre is, as a UR program sets
it (URScript `set_payload(m, cog)`, ur_rtde `setPayload(mass, cog)`).

Why a command of its own over `set_params`' `payload` parameter: a UR program speaks of mass
and centre of gravity, not of a parameter list; the write is the same (the flange body's mass,
centre and inertia, `params.payload`), so this command only names its fields the robot's way
and checks them against the UR10e's rated payload.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any

from pydantic import Field

from service.core.commands.base import Door
from service.core.commands.fields import FiniteFloat, Strict, example_config
from service.core.commands.params import (
    PAYLOAD_MASS,
    PAYLOAD_REACH,
    SetParams,
)
from service.core.errors import BadCommand

__all__ = ["PayloadValues", "SetPayload"]


class PayloadValues(Strict):
    """One world's payload: `mass` [kg] at `cog` [m] in the flange frame."""

    mass: FiniteFloat = Field(ge=0, le=PAYLOAD_MASS, description="kg; 0 takes the payload off")
    cog: list[Annotated[FiniteFloat, Field(ge=-PAYLOAD_REACH, le=PAYLOAD_REACH)]] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0],
        min_length=3,
        max_length=3,
        description=f"centre of gravity x y z [m] in the flange frame, each within "
        f"±{PAYLOAD_REACH:g} m",
    )

    model_config = example_config({"mass": 1.5, "cog": [0, 0, 0.08]})


def _number(value: Any, field: str, low: float, high: float, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise BadCommand(field, f"must be a finite number ({unit}), got {value!r}")
    if not low <= value <= high:
        raise BadCommand(field, f"{value} is outside {low:g}..{high:g} {unit}")
    return float(value)


@dataclass(frozen=True)
class SetPayload(SetParams, kind="set_payload", op="set_payload", http=("payload",)):
    """Payloads of any worlds, written together at one tick boundary: `set_params` of the
    `payload` parameter, given and recorded as mass and centre (its stage and ack are theirs)."""

    @classmethod
    def create(cls, door: Door, items: Sequence[Mapping[str, Any]]) -> SetPayload:
        cls.counted(items, "payload")
        kept: list[dict[str, Any]] = []
        for i, item in enumerate(items):
            where = f"writes.{i}." if len(items) > 1 else ""
            if not isinstance(item, Mapping) or set(item) - {"world", "mass", "cog"}:
                raise BadCommand(where or "body", "a payload is {mass, cog}")
            mass = _number(item.get("mass"), f"{where}mass", 0.0, PAYLOAD_MASS, "kg")
            cog = item.get("cog", [0.0, 0.0, 0.0])
            if not isinstance(cog, list | tuple) or len(cog) != 3:
                raise BadCommand(f"{where}cog", f"must be 3 numbers x y z [m], got {cog!r}")
            r = PAYLOAD_REACH
            xyz = [_number(v, f"{where}cog.{k}", -r, r, "m") for k, v in enumerate(cog)]
            kept.append({"world": item.get("world"), "mass": mass, "cog": xyz})
        asked = [{"world": k["world"], "params": {"payload": [k["mass"], *k["cog"]]}} for k in kept]
        return cls(SetParams.create(door, asked).writes, tuple(kept))
