"""The one world-list parser: "0-63,70,72-75" wherever a list of worlds is written.

HTTP and WebSocket `worlds` queries, the ROS 2 per-world topics (`ros2_worlds`), and the worlds
a recording or the Foxglove server covers all read the same syntax here, with the same errors.
Core: imports only core errors.
"""

from __future__ import annotations

import re

import numpy as np

from service.core.errors import ArmfleetError, BadCommand, UnknownWorld

# The `worlds` query: ids and inclusive ranges, comma-separated, no spaces. A range may be
# written either way round ("7-3" is 3..7), so that every string of this shape is meaningful.
WORLDS_PATTERN = r"^[0-9]+(-[0-9]+)?(,[0-9]+(-[0-9]+)?)*$"
_WORLDS_RE = re.compile(WORLDS_PATTERN)
_MAX_ID_DIGITS = 18  # longer ids cannot exist (and int() refuses over 4300 digits)


def parse_worlds(spec: str, nworld: int) -> np.ndarray:
    """'0-63,70,72-75' (the `worlds` query of HTTP and WebSocket) → sorted unique world ids.

    BadCommand for text not of WORLDS_PATTERN, UnknownWorld for ids that do not exist.
    """
    if not _WORLDS_RE.fullmatch(spec):
        raise BadCommand(_WORLDS, f"{spec[:40]!r} is not a list of ids and ranges like 0-63,70")
    out: set[int] = set()
    for part in spec.split(","):
        ends = part.split("-")
        if any(len(e.lstrip("0")) > _MAX_ID_DIGITS for e in ends):
            raise UnknownWorld(part[:40], nworld)
        lo, hi = sorted(int(e) for e in (ends[0], ends[-1]))
        if hi >= nworld:
            raise UnknownWorld(part, nworld)
        out.update(range(lo, hi + 1))
    return np.array(sorted(out), dtype=np.int64)


_WORLDS = "query.worlds"


def pick_worlds(spec: str | None, nworld: int, default_count: int = 8) -> list[int]:
    """Worlds an add-on (recorder, Foxglove) covers: `spec` parsed strictly, or by default the
    first `default_count` (all of a smaller batch)."""
    if spec is None:
        return list(range(min(default_count, nworld)))
    return [int(w) for w in parse_worlds(spec, nworld)]


def world_list(spec: str | None, nworld: int, setting: str) -> tuple[int, ...]:
    """A setting's world list ('0-7,9' → (0, ..., 7, 9)); empty or None → none at all.

    ValueError naming the setting and the bad part (settings are checked at start, not served).
    """
    if not spec or not spec.strip():
        return ()
    try:
        return tuple(int(w) for w in parse_worlds(spec, nworld))
    except ArmfleetError as exc:
        raise ValueError(f"{setting} {spec!r}: {exc.detail}") from None
