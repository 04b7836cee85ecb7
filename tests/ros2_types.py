"""ROS 2 message types for test peers, built from rosbags' definitions (no armfleet code).

cyclonedds needs a declared type to create a topic; instead of writing each one by hand (and
repeating armfleet's own declarations), the peer builds them from rosbags' ROS 2 Humble
typestore, plus the control_msgs / action definitions registered here from their .msg and
.action text (tests/ros2_defs.py). The bytes themselves are always serialised and decoded by
rosbags, so armfleet's CDR is judged by an independent implementation.
"""

from __future__ import annotations

import types
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype

from tests.ros2_defs import DEFINITIONS

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
for _name, _text in DEFINITIONS.items():
    # rosbags files `pkg/srv/X` under `pkg/srv/msg/X`; keep the name ROS 2 gives it
    TYPESTORE.register({_name: next(iter(get_types_from_msg(_text, _name).values()))})

_BASE = {
    "bool": bool,
    "byte": t.uint8,
    "char": t.uint8,
    "int8": t.int8,
    "uint8": t.uint8,
    "int16": t.int16,
    "uint16": t.uint16,
    "int32": t.int32,
    "uint32": t.uint32,
    "int64": t.int64,
    "uint64": t.uint64,
    "float32": t.float32,
    "float64": t.float64,
}
_CACHE: dict[tuple[str, bool], type] = {}


def dds_type_name(ros_type: str) -> str:
    """`pkg/msg/Type` → `pkg::msg::dds_::Type_` (the rmw convention)."""
    pkg, kind, name = ros_type.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def _field_type(node: tuple) -> Any:
    kind, arg = node
    if kind == Nodetype.BASE:
        name, bound = arg
        if name == "string":
            return t.bounded_str[bound] if bound else str
        return _BASE[name]
    if kind == Nodetype.NAME:
        return idl_type(arg)
    inner, size = arg
    if kind == Nodetype.ARRAY:
        return t.array[_field_type(inner), size]
    return t.sequence[_field_type(inner), size] if size else t.sequence[_field_type(inner)]


def idl_type(ros_type: str, request_header: bool = False) -> type:
    """A cyclonedds struct of `ros_type`'s layout and DDS name; with `request_header`, the
    16 bytes rmw_cyclonedds puts before a service request or reply (client guid, sequence)."""
    key = (ros_type, request_header)
    if key in _CACHE:
        return _CACHE[key]
    _, fields = TYPESTORE.fielddefs[ros_type]
    annotations: dict[str, Any] = {}
    if request_header:
        annotations |= {"client_guid": t.uint64, "sequence_number": t.int64}
    for name, node in fields:
        annotations[name] = _field_type(node)

    def body(ns: dict[str, Any]) -> None:
        ns["__annotations__"] = annotations
        for name in annotations:
            ns[name] = field(default=None)

    cls = types.new_class(
        ros_type.replace("/", "_"), (IdlStruct,), {"typename": dds_type_name(ros_type)}, body
    )
    _CACHE[key] = dataclass(cls)
    return _CACHE[key]


def to_dict(value: Any) -> Any:
    """A rosbags message → plain JSON-able values (arrays as lists)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list):
        return [to_dict(v) for v in value]
    if hasattr(value, "__msgtype__"):
        _, fields = TYPESTORE.fielddefs[value.__msgtype__]
        return {k: to_dict(getattr(value, k)) for k, _ in fields}
    if isinstance(value, np.generic):
        return value.item()
    return value


def from_dict(ros_type: str, value: dict[str, Any]) -> Any:
    """Plain values → a rosbags message; missing fields get ROS defaults (zero, empty)."""
    _, fields = TYPESTORE.fielddefs[ros_type]
    out = {}
    for name, node in fields:
        out[name] = _value(node, value.get(name))
    return TYPESTORE.types[ros_type](**out)


def _value(node: tuple, given: Any) -> Any:
    kind, arg = node
    if kind == Nodetype.BASE:
        name = arg[0]
        if name == "string":
            return given or ""
        if name == "bool":
            return bool(given)
        dtype = np.dtype("uint8" if name in ("byte", "char") else name)
        return dtype.type(given or 0)
    if kind == Nodetype.NAME:
        return from_dict(arg, given or {})
    inner, size = arg
    items = list(given) if given is not None else []
    if kind == Nodetype.ARRAY and not items:
        items = [None] * size
    if inner[0] == Nodetype.BASE and inner[1][0] != "string":
        name = inner[1][0]
        dtype = np.dtype("uint8" if name in ("byte", "char") else name)
        return np.array([v or 0 for v in items], dtype=dtype)
    return [_value(inner, v) for v in items]


def serialize(ros_type: str, value: dict[str, Any]) -> bytes:
    return bytes(TYPESTORE.serialize_cdr(from_dict(ros_type, value), ros_type))


def deserialize(ros_type: str, raw: bytes) -> dict[str, Any]:
    return to_dict(TYPESTORE.deserialize_cdr(raw, ros_type))
