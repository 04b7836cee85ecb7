"""The token the node presents to armfleet: `ARMFLEET_TOKEN` from its environment.

`armfleet serve --ros2 --token ...` hands the child its administrator token this way (never on
the command line, where `ps` shows it to every user; never as a ROS parameter, which
`ros2 param get` shows to every node on the graph). Started by hand, the node takes the same
variable as `armfleet serve` does. It travels as `Authorization: Bearer` on every HTTP request
and WebSocket handshake, as armfleet's client library sends it.
"""

from __future__ import annotations

import os

from clients.calls import auth_headers

TOKEN_ENV = "ARMFLEET_TOKEN"


def token() -> str | None:
    """The token to present, or None (armfleet on loopback without `--token`)."""
    return os.environ.get(TOKEN_ENV) or None


def headers() -> dict[str, str]:
    """The handshake headers of the node's WebSockets (empty without a token)."""
    return auth_headers(token())
