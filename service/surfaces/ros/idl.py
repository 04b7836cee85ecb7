"""Cyclone DDS types from ROS 2 message text: the one place the rosidl naming rules live.

armfleet declares each message it speaks as its .msg fields (`float64[] positions`,
`builtin_interfaces/Time stamp`, `string<=256 node_name`, `uint8[16] uuid`, `float64 w 1`),
and `message` turns them into what rosidl + rmw_cyclonedds would: a dataclass `IdlStruct` named
`pkg::kind::dds_::Type_` with the same members in the same order. Writing the .msg text instead
of hand-made classes keeps every declaration checkable against its ROS source at a glance and
the type-name rule in one function. tests/test_ros2.py, test_ros_ur.py and test_ros_actions.py
check the bytes against rosbags' independent definitions.

Types refer to types declared before them, by ROS name (`pkg/Type` for `pkg/msg/Type`, or the
full `pkg/kind/Type`). No `from __future__ import annotations`: cyclonedds reads the member
types when the class is created.
"""

import dataclasses
import types
from typing import Any

from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t

# ROS 2's numeric type names are cyclonedds' own; byte and char are octets.
_NUMBERS = ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float32")
_BASE: dict[str, Any] = {"bool": bool, "byte": t.uint8, "char": t.uint8, "float64": t.float64}
_BASE |= {name: getattr(t, name) for name in _NUMBERS}
_DECLARED: dict[str, type] = {}

# What rmw_cyclonedds puts before a service request or reply: the client and its sequence number.
REQUEST_HEADER = "uint64 client_guid\nint64 sequence_number\n"


def dds_name(ros_type: str) -> str:
    """`pkg/msg/Type` → `pkg::msg::dds_::Type_`, the DDS type name ROS 2 nodes use."""
    pkg, kind, name = ros_type.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def _declared(name: str, pkg: str) -> type:
    """A type declared before, by its name in a .msg: `Type` (of the same package), `pkg/Type`
    (a message) or `pkg/kind/Type`."""
    parts = name.split("/")
    if len(parts) == 1:
        parts = [pkg, *parts]
    full = "/".join((parts[0], "msg", parts[1]) if len(parts) == 2 else parts)
    if full not in _DECLARED:
        raise KeyError(f"{full} is used before it is declared")
    return _DECLARED[full]


def _scalar(spec: str, pkg: str) -> tuple[Any, Any]:
    """A .msg element type → (its cyclonedds type, its default: a value or a factory)."""
    if spec.startswith("string"):
        bound = spec.partition("<=")[2]
        return (t.bounded_str[int(bound)] if bound else str), ""
    if spec in _BASE:
        return _BASE[spec], (False if spec == "bool" else 0.0 if "float" in spec else 0)
    cls = _declared(spec, pkg)
    return cls, cls


def _member(spec: str, default: str | None, pkg: str) -> tuple[Any, dataclasses.Field]:
    """One field line's type spec (`float64`, `T[]`, `T[16]`, `T[<=8]`) and its optional
    default (`1`, `"/"`) → the member's type and its dataclass field."""
    element, bracket, size = spec.partition("[")
    kind, zero = _scalar(element, pkg)
    if not bracket:
        if default is not None:
            value = default.strip('"') if zero == "" else type(zero)(float(default))
            return kind, dataclasses.field(default=value)
        if isinstance(zero, type):
            return kind, dataclasses.field(default_factory=zero)
        return kind, dataclasses.field(default=zero)
    size = size.rstrip("]")
    if size and not size.startswith("<="):
        n = int(size)
        fill = (
            (lambda: [zero() for _ in range(n)]) if isinstance(zero, type) else lambda: [zero] * n
        )
        return t.array[kind, n], dataclasses.field(default_factory=fill)
    listed = t.sequence[kind, int(size[2:])] if size else t.sequence[kind]
    return listed, dataclasses.field(default_factory=list)


def message(ros_type: str, fields: str) -> type:
    """Declare `ros_type` (`pkg/kind/Type`) from its .msg field lines (`type name [default]`;
    `#` comments and blank lines are skipped)."""
    pkg = ros_type.split("/")[0]
    annotations: dict[str, Any] = {}
    defaults: dict[str, dataclasses.Field] = {}
    for line in fields.splitlines():
        words = line.partition("#")[0].split(maxsplit=2)
        if words:
            default = words[2] if len(words) > 2 else None
            annotations[words[1]], defaults[words[1]] = _member(words[0], default, pkg)

    def body(ns: dict[str, Any]) -> None:
        ns["__annotations__"] = annotations
        ns.update(defaults)

    name = ros_type.rsplit("/", 1)[1]
    cls = types.new_class(name, (IdlStruct,), {"typename": dds_name(ros_type)}, body)
    _DECLARED[ros_type] = dataclasses.dataclass(cls)
    return _DECLARED[ros_type]
