"""service/heap.py: with glibc told to keep large blocks, a freed 64 MB buffer stays mapped
for the next one (the resident size does not drop on free), also one made on another thread
(the render and packing threads); without, it is unmapped."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import ROOT

CHILD = """
import sys, threading
from service import heap
if sys.argv[1] == "keep":
    assert heap.keep_large_blocks()
def rss():
    return int(open("/proc/self/statm").read().split()[1]) * 4096
def freed():
    buf = b"x" * (64 << 20)  # written: every page resident
    with_buf = rss()
    del buf
    print(with_buf - rss())
freed()
thread = threading.Thread(target=freed)
thread.start()
thread.join()
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_a_freed_large_buffer_stays_mapped_only_when_kept() -> None:
    def freed(how: str) -> list[int]:
        out = subprocess.run(
            [sys.executable, "-c", CHILD, how], cwd=ROOT, capture_output=True, text=True, check=True
        )
        return [int(x) for x in out.stdout.split()]  # main thread, another thread

    assert all(x > 60 << 20 for x in freed("plain"))  # unmapped on free
    assert all(x < 4 << 20 for x in freed("keep"))  # kept for the next large buffer
