"""The JSON op protocol of the WebSocket sockets: one client message → one ack or error frame.

`{"op": <a command's op>, "id": ..., "world": ..., ...fields}`: the op names a command class
of the registry (service.core.commands.registry.BY_OP), which parses the rest of the body and
writes the ack; Control runs it. On a socket bound to one world, `world` may be left out and
must match when given. Never raises: every refusal is an error frame naming the field.
"""

from __future__ import annotations

from typing import Any

import orjson

from service.core.commands.control import Control
from service.core.commands.registry import BY_OP
from service.core.errors import ArmfleetError, BadCommand
from service.core.streams import wire


def handle_text(
    control: Control, text: str, default_world: int | None, source: str
) -> tuple[dict[str, Any], str]:
    """One client text frame → (ack or error frame, the command kind for metrics)."""
    try:
        msg = orjson.loads(text)
    except orjson.JSONDecodeError as exc:
        # NaN/Infinity are not JSON, but the rest of such a message is readable: parse it
        # leniently so that the error names the field and echoes the client's id.
        msg = wire.loads_lenient(text)
        if msg is None:
            return wire.error_frame(wire.read_id(text), f"malformed JSON: {exc}"), "unknown"
    return handle(control, msg, default_world, source)


def handle(
    control: Control, msg: Any, default_world: int | None, source: str
) -> tuple[dict[str, Any], str]:
    """One decoded client message → (ack or error frame, the command kind for metrics)."""
    msg_id = msg.get("id") if isinstance(msg, dict) else None
    kind = "unknown"
    try:
        if not isinstance(msg, dict):
            raise BadCommand("message", "a message must be a JSON object with an `op`")
        body = {k: v for k, v in msg.items() if k not in ("id", "op", "world")}
        op = msg.get("op")
        command_class = BY_OP.get(op) if isinstance(op, str) else None
        if command_class is not None:
            kind = command_class.kind
        world = msg.get("world", default_world)
        if default_world is not None and world != default_world:
            raise BadCommand("world", f"this socket controls world {default_world} only")
        if world is None:
            raise BadCommand("world", "`world` (an integer id) is required on this socket")
        world = control.world(world)
        if command_class is None:
            raise BadCommand("op", f"unknown op {op!r}; ops are {sorted(BY_OP)}")
        command = command_class.from_wire(control, world, body)
        result = control.run(command, source)
        return command.ack(control, msg_id, world, result), kind
    except ArmfleetError as exc:
        return wire.error_frame(msg_id, exc), kind


def kind_of(text: str) -> str:
    """The command kind a text frame asks for (for counting refusals; never raises)."""
    try:
        op = orjson.loads(text).get("op")
    except (orjson.JSONDecodeError, AttributeError):
        return "unknown"
    command_class = BY_OP.get(op) if isinstance(op, str) else None
    return "unknown" if command_class is None else command_class.kind
