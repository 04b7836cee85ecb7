"""The field types and checks the wire contract is built from (schemas.py holds the models).

Every rule a request field has is stated twice, once as a check and once in its JSON Schema, so
that what the schema calls valid is accepted and what it calls invalid is refused. Joint names
come from the model, read on first use: importing this module compiles nothing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated, Any, ClassVar, Literal, Self

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
    WithJsonSchema,
    model_validator,
)

from service.core.sim.robot import default_spec
from service.core.sim.types import NJOINT

# Strict: numbers only ("0.1" and true are refused); ints are fine.
FiniteFloat = Annotated[float, Field(allow_inf_nan=False, strict=True)]


def bounded_float(lo: float, hi: float, description: str) -> Any:
    """A strict finite number in [lo, hi], the bounds stated in the schema too."""
    field = Field(allow_inf_nan=False, strict=True, ge=lo, le=hi, description=description)
    return Annotated[float, field]


Delta = bounded_float(-2 * math.pi, 2 * math.pi, "rad, |delta| <= 2π")


def paired(keys_name: str, keys: list, values_name: str, values: list) -> None:
    """Parallel lists (JointState's name/position, worlds/position): same length, keys unique."""
    if len(keys) != len(values):
        raise ValueError(
            f"{keys_name} and {values_name} must have the same length "
            f"(got {len(keys)} and {len(values)})"
        )
    if len(set(keys)) != len(keys):
        raise ValueError(f"{keys_name} lists an entry twice")


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Paired(Strict):
    """A request of two parallel lists, `PAIR` = (keys, values): checked with `paired`, and
    stated in the schema by `paired_config`."""

    PAIR: ClassVar[tuple[str, str]]

    @model_validator(mode="after")
    def _same_length(self) -> Self:
        keys, values = self.PAIR
        paired(keys, getattr(self, keys), values, getattr(self, values))
        return self


def paired_config(
    pair: tuple[str, str],
    most: int,
    example: dict[str, Any],
    extra: Literal["allow", "forbid"] = "forbid",
) -> ConfigDict:
    """A `Paired` model's config: its example, and equal lengths (1..`most`) in its schema."""
    lengths = equal_lengths(*pair, range(1, most + 1))
    return ConfigDict(extra=extra, json_schema_extra={"examples": [example], "oneOf": lengths})


def example_config(example: dict[str, Any]) -> ConfigDict:
    """A `Strict` model's config (no field besides its own) with `example` in its schema."""
    return ConfigDict(extra="forbid", json_schema_extra={"examples": [example]})


# The joint names come from the model (service/core/sim/robot.py), read when a request is first
# validated or the OpenAPI document first built, not when this module is imported: importing
# the contract must not compile the MJCF.
def joint_names() -> tuple[str, ...]:
    return tuple(default_spec().names)


def _joint_keys() -> tuple[str, ...]:
    """Names or "0".."6": how a joint is named as a JSON object key."""
    return (*joint_names(), *(str(i) for i in range(NJOINT)))


def _joint_key(value: object) -> str:
    """A joint named by its name or by its index as a string (JSON object keys are strings)."""
    if not isinstance(value, str):
        raise ValueError(f"a joint is named by a string, got {value!r}")
    if value not in _joint_keys():
        raise ValueError(f"unknown joint {value!r}; joints are {list(joint_names())} (or 0..6)")
    return value


def _joint_ref(value: object) -> str | int:
    """A joint named by its name or its index 0..6 (booleans are not indices; 2.0 is 2)."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, int) and not isinstance(value, bool):
        if not 0 <= value < NJOINT:
            raise ValueError(f"joint index {value} out of range 0..{NJOINT - 1}")
        return value
    return _joint_key(value)


class LazyJsonSchema:
    """`WithJsonSchema`, but the schema is made when the document is built (it names joints)."""

    def __init__(self, make: Callable[[], dict[str, Any]]) -> None:
        self._make = make

    def __get_pydantic_json_schema__(self, core_schema: Any, handler: Any) -> dict[str, Any]:
        return self._make()


JointKey = Annotated[
    str,
    PlainValidator(_joint_key),
    LazyJsonSchema(
        lambda: {
            "type": "string",
            "enum": list(_joint_keys()),
            "description": "joint name, or its index as a string",
        }
    ),
]
JointRef = Annotated[
    str | int,
    PlainValidator(_joint_ref),
    LazyJsonSchema(
        lambda: {
            "anyOf": [
                {"type": "string", "enum": list(joint_names())},
                {"type": "integer", "minimum": 0, "maximum": NJOINT - 1},
            ],
            "description": "joint name or index 0..6",
        }
    ),
]


def json_int(minimum: int | None = None, maximum: int | None = None, description: str = "") -> Any:
    """An integer as JSON Schema means it: 3 and 3.0 (JSON has one number type), never true/false
    (Python's bools are ints), "3" or 3.5; with optional bounds, stated in the schema too."""

    def check(value: object) -> int:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"must be an integer, got {value!r}")
        if isinstance(value, float) and not value.is_integer():
            raise ValueError(f"must be an integer, got {value!r}")
        number = int(value)
        if minimum is not None and number < minimum:
            raise ValueError(f"must be >= {minimum}, got {number}")
        if maximum is not None and number > maximum:
            raise ValueError(f"must be <= {maximum}, got {number}")
        return number

    schema: dict[str, Any] = {"type": "integer"}
    if minimum is not None:
        schema["minimum"] = minimum
    if maximum is not None:
        schema["maximum"] = maximum
    if description:
        schema["description"] = description
    return Annotated[int, PlainValidator(check), WithJsonSchema(schema)]


WorldId = json_int(minimum=0, description="world index")


def equal_lengths(a: str, b: str, lengths: range) -> list[dict[str, Any]]:
    """oneOf branches saying arrays `a` and `b` have the same length (JSON Schema cannot
    compare two arrays, so every allowed length is listed)."""
    return [
        {"properties": {a: {"minItems": k, "maxItems": k}, b: {"minItems": k, "maxItems": k}}}
        for k in lengths
    ]


def non_null(prop: dict[str, Any]) -> dict[str, Any]:
    """`X | None` as pydantic writes it (anyOf [X, null]) → X, keeping description/title."""
    if "anyOf" not in prop:
        return prop
    kept = [p for p in prop["anyOf"] if p.get("type") != "null"]
    out = {k: v for k, v in prop.items() if k not in ("anyOf", "default")}
    if len(kept) == 1:
        out.update(kept[0])
    else:
        out["anyOf"] = kept
    return out
