"""A primary-interface robot message (type 20, a text message): how a robot's log lines reach
the clients of its primary and secondary ports.

Why a module of its own: the world's controller (world_robot.py) sends these when it refuses
or stops something, and the script ports send them too; neither may import the other.
"""

from __future__ import annotations

import struct
import time

ROBOT_MESSAGE, TEXT, SOURCE_CONTROLLER = 20, 0, -2


def robot_message(text: str) -> bytes:
    """A primary-interface robot message package: size, type 20, timestamp, source, type 0."""
    body = struct.pack(">QbB", int(time.time() * 1000), SOURCE_CONTROLLER, TEXT)
    body += text.encode("utf-8", "replace")[:1000]
    return struct.pack(">iB", 5 + len(body), ROBOT_MESSAGE) + body
