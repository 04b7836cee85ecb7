"""RTDE's framing and its control packages, protocol version 2 (UR's RTDE guide).

Every package is a header, uint16 size (header included) and uint8 type, then its payload, all
big-endian. Why a module of its own: the session (rtde_session.py) speaks in packages and
never in bytes, and tests read the same constants.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")
PROTOCOL_VERSION = 2
HEADER = struct.Struct(">HB")
MAX_PACKAGE = 0xFFFF
MAX_NAMES = 2048  # bytes of variable names a recipe may list (the RTDE guide's limit)
# A UR10e e-Series controller as ur_rtde sees it: a major version above 3 means 500 Hz.
CONTROL_VERSION = (5, 21, 0, 0)
MAX_FREQUENCY = 500.0

# Text message levels (v2)
EXCEPTION, ERROR, WARNING, INFO = 0, 1, 2, 3


class Malformed(ValueError):
    """A package that cannot be read: the session answers or closes, and logs why."""


@dataclass(frozen=True)
class Package:
    kind: int
    payload: bytes

    @property
    def name(self) -> str:
        return chr(self.kind) if 32 <= self.kind < 127 else f"0x{self.kind:02x}"


def frame(kind: int, payload: bytes = b"") -> bytes:
    return HEADER.pack(HEADER.size + len(payload), kind) + payload


def split(buffer: bytearray) -> list[Package]:
    """The whole packages at the front of `buffer` (removed from it); Malformed for a header
    whose size is below the header's own."""
    out: list[Package] = []
    while len(buffer) >= HEADER.size:
        size, kind = HEADER.unpack_from(buffer)
        if size < HEADER.size:
            raise Malformed(f"a package of size {size} (the header alone is {HEADER.size})")
        if len(buffer) < size:
            break
        out.append(Package(kind, bytes(buffer[HEADER.size : size])))
        del buffer[:size]
    return out


def accepted(kind: int, ok: bool) -> bytes:
    """The one-byte answer of V, S and P."""
    return frame(kind, bytes([1 if ok else 0]))


def control_version() -> bytes:
    return frame(GET_URCONTROL_VERSION, struct.pack(">IIII", *CONTROL_VERSION))


def text(message: str, source: str = "armfleet", level: int = WARNING) -> bytes:
    """A v2 text message: uint8 length, message, uint8 length, source, uint8 level."""
    msg = message.encode("utf-8", "replace")[:255]
    src = source.encode("utf-8", "replace")[:255]
    return frame(TEXT_MESSAGE, bytes([len(msg)]) + msg + bytes([len(src)]) + src + bytes([level]))


def read_text(payload: bytes) -> tuple[str, str, int]:
    """(message, source, level) of a client's v2 text message; Malformed when it is short."""
    try:
        n = payload[0]
        msg = payload[1 : 1 + n]
        m = payload[1 + n]
        src = payload[2 + n : 2 + n + m]
        level = payload[2 + n + m]
    except IndexError:
        raise Malformed("a text message shorter than its lengths say") from None
    return msg.decode("utf-8", "replace"), src.decode("utf-8", "replace"), level


def recipe_answer(kind: int, recipe_id: int, types: list[str]) -> bytes:
    return frame(kind, bytes([recipe_id]) + ",".join(types).encode())


def names_of(payload: bytes) -> list[str]:
    """Comma-separated variable names (a trailing comma, as ur_rtde sends, ends the list)."""
    if len(payload) > MAX_NAMES:
        raise Malformed(f"{len(payload)} bytes of variable names (at most {MAX_NAMES})")
    try:
        text_ = payload.decode("ascii")
    except UnicodeDecodeError:
        raise Malformed("variable names are not ASCII") from None
    names = [n.strip() for n in text_.split(",")]
    while names and not names[-1]:
        names.pop()
    if not names:
        raise Malformed("a recipe with no variables")
    return names
