"""The service's binary messages, described once for the side that writes them and the side that
reads them: the service builds its frames from these constants (service/core/streams/wire.py,
service/core/cameras/wire.py), the client library, the ROS node and the tests read them here.

Why in the client: the client library installs alone (packaging/armfleet-client), so the one
description both sides share must live where the client can import it; the service may import
the client's public modules, the client never imports the service.

State frames (`/v1/ws?format=binary`): `BINARY_MAGIC`, u32 header length, the JSON header
(`op`, `tick`, `n`, `name`, `columns`: `BINARY_COLUMNS`), int32[n] world ids, then one float32
row per world holding the columns side by side. Asked with `entities=true`, the header also has
`"entities": {"name": [...], "columns": ENTITY_COLUMNS}` and the rows are followed by
float32[n, ne, 13]: per world, per entity (in `name` order) its position, orientation
(w x y z), linear and angular velocity side by side. All little-endian.

Pose frames (the browser page's `/v1/ws/view`): `POSE_MAGIC`; layout in
service/core/streams/wire.py beside `pose_frame`.

Image messages (`/v1/ws/cameras`, GET /v1/cameras/{name}/images): `IMAGE_MAGIC`, u32 header
length, the JSON header (tick, worlds, camera, ..., `sizes`), then the images back to back;
`unpack_images` reads one.
"""

from __future__ import annotations

import struct
from typing import Any

import orjson

BINARY_MAGIC = b"AFS1"
BINARY_COLUMNS = (
    ("sim_time", 1),
    ("position", 7),
    ("velocity", 7),
    ("effort", 7),
    ("target", 7),
    ("flange_position", 3),
    ("flange_quaternion", 4),
    ("faults", 1),
)
ENTITY_COLUMNS = (("position", 3), ("orientation", 4), ("linear", 3), ("angular", 3))
POSE_MAGIC = b"AFP1"
IMAGE_MAGIC = b"AFIM"
HEADER_LENGTH = struct.Struct("<I")  # after the magic, in every message above


def unpack_images(message: bytes) -> tuple[dict[str, Any], list[bytes]]:
    """(header, images) of one image message; ValueError when it is not one."""
    if message[:4] != IMAGE_MAGIC:
        raise ValueError("not an armfleet images message")
    (n,) = HEADER_LENGTH.unpack_from(message, 4)
    header = orjson.loads(message[8 : 8 + n])
    out, at = [], 8 + n
    for size in header["sizes"]:
        out.append(message[at : at + size])
        at += size
    return header, out
