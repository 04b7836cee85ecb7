"""Keep a sourced ROS 2 shell's PYTHONPATH out of armfleet's own interpreter.

`source /opt/ros/humble/setup.bash` puts ROS's packages, built for the distribution's Python
(Humble: 3.10, Jazzy: 3.12), on PYTHONPATH; armfleet's Python (3.11+) would import them ahead
of its own environment. Called first thing on import of `service`: entries that belong to
another Python version, to an ament prefix (AMENT_PREFIX_PATH) or hold rclpy are taken off
`sys.path` and the environment (so armfleet's worker processes are clean too); the original
value is kept in ARMFLEET_ROS2_PYTHONPATH for the ROS 2 node armfleet starts with that ROS.
Any other entry (a checkout put there on purpose) stays.
"""

from __future__ import annotations

import os
import re
import sys

ORIGINAL = "ARMFLEET_ROS2_PYTHONPATH"
_VERSION = re.compile(r"python(\d+)\.(\d+)")


def foreign(entry: str, prefixes: list[str]) -> bool:
    """True for a PYTHONPATH entry that is another Python's or ROS's packages."""
    if not entry:
        return False
    m = _VERSION.search(entry)
    if m and (int(m.group(1)), int(m.group(2))) != sys.version_info[:2]:
        return True
    if any(p and (entry == p or entry.startswith(p.rstrip("/") + "/")) for p in prefixes):
        return True
    return os.path.isdir(os.path.join(entry, "rclpy"))


def scrub() -> list[str]:
    """Drop foreign PYTHONPATH entries from sys.path and the environment; the dropped ones."""
    value = os.environ.get("PYTHONPATH")
    if not value:
        return []
    prefixes = os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
    entries = value.split(os.pathsep)
    dropped = [e for e in entries if foreign(e, prefixes)]
    if not dropped:
        return []
    os.environ.setdefault(ORIGINAL, value)
    kept = [e for e in entries if e not in dropped]
    if kept:
        os.environ["PYTHONPATH"] = os.pathsep.join(kept)
    else:
        del os.environ["PYTHONPATH"]
    gone = {os.path.abspath(e) for e in dropped}
    sys.path[:] = [p for p in sys.path if not p or os.path.abspath(p) not in gone]
    return dropped
