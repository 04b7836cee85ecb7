"""Spawned workers that do not import the serving process's main module again.

Why: a "spawn" child re-imports the parent's `__main__` before it unpickles its target
(multiprocessing.spawn.prepare: by module name for `python -m service.cli`, by path for the
`armfleet` script), so every shard worker first ran `service/cli.py` as `__mp_main__`: typer,
the settings of every surface and what they import, a few tenths of a CPU-second, for nothing
(a `--shards 2` worker's start, with the lazy `clients` package: 5.6 -> 4.8 CPU-s, medians of 5):
a worker's target (shard_worker.worker) and its arguments are pickled by reference to their own
modules, never to `__main__`. What the main module set that a child needs travels anyway:
`os.environ` (e.g. MUJOCO_GL, set by service/cli.py) and `sys.path` are passed to every child.

How: while a child is started, `sys.modules["__main__"]` is a bare module with neither a
`__spec__` nor a `__file__`, the one case in which spawn's preparation data names no main
module to import (Python 3.8-3.13's multiprocessing.spawn.get_preparation_data). The real
main module is back as soon as `start()` has written the preparation data; the swap is
serialised by a lock, and it is only ever done around `Process.start()`.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import types
from collections.abc import Iterator

_LOCK = threading.Lock()


@contextlib.contextmanager
def main_not_reimported() -> Iterator[None]:
    """Around `Process.start()` of a "spawn" context: the child imports no `__main__`."""
    with _LOCK:
        main = sys.modules["__main__"]
        sys.modules["__main__"] = types.ModuleType("__main__")  # no __spec__, no __file__
        try:
            yield
        finally:
            sys.modules["__main__"] = main
