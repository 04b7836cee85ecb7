"""The service's binary messages, described once for the side that writes them and the side that
reads them: the service builds its frames from these constants (service/core/streams/wire.py,
service/core/cameras/wire.py), the client library, the ROS node and the tests read them here.

Why in the client: the client library installs alone (packaging/armfleet-client), so the one
description both sides share must live where the client can import it; the service may import
the client's public modules, the client never imports the service.

State frames (`/v1/ws?format=binary`), layout 2: `BINARY_MAGIC`, u32 header length, the JSON
header (`op`, `tick`, `n`, `name`, `columns`: `BINARY_COLUMNS`, `layout`: 2), int32[n] world
ids, then one float32 row per world holding the columns side by side. Asked with
`entities=true`, the header also has `"entities": {"name": [...], "columns": ENTITY_COLUMNS}`
and the rows are followed by float32[n, ne, 13]: per world, per entity (in `name` order) its
position, orientation (w x y z), linear and angular velocity side by side. Last, uint8[n]: each
world's safety mode as UR numbers it (`SAFETY_MODES`: 1 NORMAL, 3 PROTECTIVE_STOP), the
`safety_mode` that JSON frames name. All little-endian.

Layouts. A frame whose header has no `layout` is layout 1 (servers before the safety block):
the same bytes without the uint8[n] at the end. Layout 2 only appends, so a reader written for
layout 1 reads a layout-2 frame unchanged (everything it reads is where it was) and sees no
safety mode; it must not insist that the frame ends after the rows or the entity block. A
reader of layout 2 tells the two apart by `layout` (`safety_modes` below: None for layout 1).
The magic changes only for a layout that a reader of the older one would misread.

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
BINARY_LAYOUT = 2  # the header's `layout`: 2 appends the safety block (see the docstring)
SAFETY_MODES = {1: "NORMAL", 3: "PROTECTIVE_STOP"}  # the safety block's numbers (UR's)
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


def safety_modes(header: dict[str, Any], data: bytes, at: int, n: int) -> tuple[str, ...] | None:
    """The safety block's n modes by name, the block starting at byte `at` of state frame
    `data` (after the rows and the entity block, if any); None for a layout-1 frame."""
    if int(header.get("layout", 1)) < 2:
        return None
    modes = data[at : at + n]
    if len(modes) != n:
        raise ValueError(f"the frame ends {n - len(modes)} bytes into its safety block")
    return tuple(SAFETY_MODES.get(m, f"MODE_{m}") for m in modes)


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
