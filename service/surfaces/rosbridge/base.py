"""What every rosbridge capability shares: the error that becomes a `status` frame, names."""

from __future__ import annotations

from typing import Any

ROSBRIDGE = "rosbridge"  # the label of commands that came over rosbridge


class ProtocolError(ValueError):
    """Client input that gets a `status` error frame; nothing changes."""


def same_type(given: str, ros2_type: str) -> bool:
    """rosbridge accepts `pkg/Type` and `pkg/msg/Type` for the same message."""
    pkg, _, name = ros2_type.partition("/msg/")
    return given in (ros2_type, f"{pkg}/{name}")


def topic_name(value: Any, what: str = "topic") -> str:
    if not isinstance(value, str) or not value:
        raise ProtocolError(f"{what}: a topic name (string) is required")
    return value if value.startswith("/") else "/" + value
