"""The end-of-run check of the servers' logs (tests/server_logs.py, run by conftest.py's
session-finish hook): what it finds, what it names, what a marked test's folder excuses."""

from __future__ import annotations

from pathlib import Path

import pytest
from server_logs import first_finding, problems

# The logs these tests write to check the check are not any server's: excused, as a test whose
# server prints a traceback on purpose would be.
pytestmark = pytest.mark.server_traceback("fake server logs written to test the log check")

TRACEBACK = """INFO:     127.0.0.1:59718 - "GET /v1/info HTTP/1.1" 200 OK
Exception in thread armfleet-ws-bulk:
Traceback (most recent call last):
  File "threading.py", line 1045, in _bootstrap_inner
concurrent.futures._base.InvalidStateError: CANCELLED
"""
LOGGING_ERROR = """--- Logging error ---
TypeError: cannot unpack non-iterable NoneType object
"""


def test_a_traceback_or_a_logging_error_is_named_with_its_file_and_first_lines(
    tmp_path: Path,
) -> None:
    clean = tmp_path / "a" / "server-1.log"
    clean.parent.mkdir()
    clean.write_text('INFO:     127.0.0.1:1 - "GET /readyz HTTP/1.1" 200 OK\n')
    broken = tmp_path / "b" / "server-2.log"
    broken.parent.mkdir()
    broken.write_text(TRACEBACK)
    logging_error = tmp_path / "server-3.log"
    logging_error.write_text(LOGGING_ERROR)
    (tmp_path / "b" / "other.log").write_text(TRACEBACK)  # not a server's log: not read
    found = problems(tmp_path)
    assert len(found) == 2
    assert found[0].startswith(f"{broken}:\nException in thread armfleet-ws-bulk:\nTraceback")
    assert "InvalidStateError" in found[0]
    assert found[1].startswith(f"{logging_error}:\n--- Logging error ---")
    assert first_finding(clean) is None


def test_the_folder_of_a_marked_test_is_excused(tmp_path: Path) -> None:
    marked = tmp_path / "test_dies0"
    marked.mkdir()
    (marked / "server-4.log").write_text(TRACEBACK)
    assert problems(tmp_path, skip=[marked]) == []
    assert len(problems(tmp_path)) == 1
