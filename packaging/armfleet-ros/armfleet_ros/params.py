"""The node's ROS parameters, declared so that any type given is taken and converted."""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import ParameterDescriptor


def param(node: Any, name: str, default: Any) -> Any:
    """A parameter of whatever type it was given (`-p worlds:=3` arrives as an integer,
    `rate:=100` too): the caller converts it; rclpy's type check never refuses it."""
    return node.declare_parameter(name, default, ParameterDescriptor(dynamic_typing=True)).value
