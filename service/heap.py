"""Large buffers reused, not mapped afresh: glibc's malloc told to keep freed memory.

glibc serves every allocation over 32 MiB with a fresh `mmap` and gives it back on free, so each
new large buffer is faulted in page by page. A camera stream of 16,384 64x64 images is 201 MB a
message, and the server makes three such buffers per message (the pixels out of the device, the
message, the WebSocket frame): on the virtual machines measured (where a page fault is dear) a
copy of 201 MB into a fresh buffer took 150 to 200 ms, into one already mapped about 25 ms, and
the service's renderer on the H100 machine went from 231 ms to 43 ms a batch with this (bench
section 30). With mmap off and the heap's top kept up to `KEEP_BYTES`, a freed buffer is
handed to the next one of its size already mapped. One arena for every thread: a thread's own
arena is made of 64 MiB heaps, and glibc maps a larger block for it afresh whatever the
settings say (a 201 MB copy in a thread took 125 ms kept that way, 20 ms with one arena); the
buffers are made on the render thread and the packing threads. Costs: memory freed stays with
the process up to `KEEP_BYTES` above what is in use, a fragmented heap can hold more, and
threads share one malloc lock (Python's small objects do not take it).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD = -1  # glibc's mallopt parameters (malloc.h)
M_MMAP_MAX = -4
M_ARENA_MAX = -8
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
    settings = ((M_ARENA_MAX, 1), (M_MMAP_MAX, 0), (M_TRIM_THRESHOLD, KEEP_BYTES))
    return all(bool(mallopt(param, value)) for param, value in settings)
