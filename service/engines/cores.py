"""How many CPU cores this process may use: the one answer every engine and the bench share.

The affinity mask, not the machine's count: in a container or under `taskset` the machine may
have more cores than this process is allowed to run on, and threads or shards beyond those
only wait for each other.
"""

from __future__ import annotations

import os


def usable_cores() -> int:
    """Cores this process may run on (the affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1
