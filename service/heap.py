"""Large buffers reused, not mapped afresh: glibc's malloc told to keep freed memory.

glibc serves every allocation over 32 MiB with a fresh `mmap` and gives it back on free, so each
new large buffer is faulted in page by page. A camera stream of 16,384 64x64 images is 201 MB a
message, and the server makes three such buffers per message (the pixels out of the device, the
message, the WebSocket frame): on the virtual machines measured (where a page fault is dear) a
copy of 201 MB into a fresh buffer took 150 to 200 ms, into one already mapped about 25 ms, and
the service's renderer on the H100 machine went from 231 ms to 43 ms a batch with this (bench
section 30). With mmap off and the heap's top kept up to `KEEP_BYTES`, a freed buffer is
handed to the next one of its size already mapped. Costs: memory freed stays with the process
up to `KEEP_BYTES` above what is in use, and a fragmented heap can hold more.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD = -1  # glibc's mallopt parameters (malloc.h)
M_MMAP_MAX = -4
KEEP_BYTES = 1 << 30  # the heap's free top is given back above this


def keep_large_blocks() -> bool:
    """Tell glibc's malloc to keep large freed blocks for reuse; False where there is no glibc
    (macOS, musl) or it refused, and nothing changes."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(M_MMAP_MAX, 0)) and bool(mallopt(M_TRIM_THRESHOLD, KEEP_BYTES))
