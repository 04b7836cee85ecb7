"""`PackedRows`: a stream frame's rows as an engine hands them over, maybe still on their way.

An engine that `PacksFrames` (service.core.sim.batch) returns one per selection;
service.core.streams.frames waits for it on the frame thread and releases it after sending.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

_NOOP: Callable[[], None] = lambda: None  # noqa: E731


@dataclass
class PackedRows:
    """A frame's float32 rows (`wire.BINARY_COLUMNS`), possibly still on their way to the host.

    `wait()` returns them (k, 37), valid until `release()`; the engine reuses the buffer after.
    An engine may hand `compute` instead of rows: `wait()` builds them then, on the frame
    thread, from copies the engine took between ticks (the native engine's flange kinematics
    then run beside the next tick instead of before it). `host`: the JSON frame's host columns
    of the same worlds (`PacksFrames.host_columns`), when the engine copied them anyway.
    """

    tick: int
    ids: np.ndarray
    rows: np.ndarray | None
    done: Any = None  # a wp.Event marking the copy's end (None: already on the host)
    release: Callable[[], None] = _NOOP
    compute: Callable[[], np.ndarray] | None = None
    host: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def wait(self) -> np.ndarray:
        if self.rows is None:
            assert self.compute is not None, "PackedRows without rows or compute"
            self.rows, self.compute = self.compute(), None
        if self.done is not None:
            import warp as wp

            wp.synchronize_event(self.done)  # a ctypes call: the GIL is released meanwhile
        return self.rows
