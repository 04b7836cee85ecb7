"""The servers' logs, read at the end of the run: no traceback and no logging error in any.

Every server the suite starts through `clients.testing.serve` with a `log_dir` writes
`server-PORT.log` there, and the fixtures put `log_dir` under pytest's temporary folders. A
traceback in one is a failure nobody asserted on (a thread that died, an error the handler let
through, a log record that could not be formatted), so conftest.py's session-finish hook runs
`problems` over the session's temporary folder (each pytest-xdist worker over its own) and
fails the run naming the file and the first lines.

A test that makes a server print a traceback on purpose says so with
`@pytest.mark.server_traceback("why")`: the logs under that test's own `tmp_path` are then
not read (a server shared by a module is never excused: such a test starts its own).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import pytest

MARKS = ("Traceback (most recent call last)", "--- Logging error ---")
FIRST_LINES = 12  # of each finding: where it starts, and what it says
MARKER = "server_traceback"
EXCUSED = pytest.StashKey[dict[Path, str]]()  # tmp_path of a marked test -> its reason


def excused(config: pytest.Config) -> dict[Path, str]:
    """The folders whose logs may hold tracebacks, with the reason the test gave."""
    return config.stash.setdefault(EXCUSED, {})


def first_finding(path: Path) -> str | None:
    """The first traceback or logging error in `path` (from the line before it, which says
    where it came from, e.g. "Exception in thread ..."), or None."""
    lines = path.read_text(errors="replace").splitlines()
    for i, line in enumerate(lines):
        if any(mark in line for mark in MARKS):
            return "\n".join(lines[max(0, i - 1) : i + FIRST_LINES])
    return None


def problems(root: Path, skip: Iterable[Path] = ()) -> list[str]:
    """Every server log under `root` (but not under a `skip` folder) that has a traceback or a
    logging error: its path and its first lines."""
    skipped = [p.resolve() for p in skip]
    out = []
    for path in sorted(root.rglob("server-*.log")):
        where = path.resolve()
        if any(where.is_relative_to(s) for s in skipped):
            continue
        found = first_finding(path)
        if found is not None:
            out.append(f"{path}:\n{found}")
    return out
