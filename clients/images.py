"""The camera stream's binary message (`/v1/ws/cameras`, GET /v1/cameras/{name}/images), read:
`AFIM`, a little-endian u32 header length, the JSON header (tick, worlds, camera, ..., `sizes`),
then the images back to back. The service writes it (service/core/cameras/wire.py); clients,
the ROS node and tests read it with `unpack`."""

from __future__ import annotations

import struct
from typing import Any

import orjson

MAGIC = b"AFIM"


def unpack(message: bytes) -> tuple[dict[str, Any], list[bytes]]:
    """(header, images) of one message; ValueError when it is not one."""
    if message[:4] != MAGIC:
        raise ValueError("not an armfleet images message")
    (n,) = struct.unpack_from("<I", message, 4)
    header = orjson.loads(message[8 : 8 + n])
    out, at = [], 8 + n
    for size in header["sizes"]:
        out.append(message[at : at + size])
        at += size
    return header, out
