"""The loop's periodic snapshot, copied to the host beside the next tick where the engine can.

Why: the loop publishes a snapshot at least every 0.1 s (`latest` for readers who do not wait
for a tick), whether or not anyone looks. On a GPU its copy to the host held up the next tick,
the device idle meanwhile: at 65,536 worlds 42 MB, ~1.7 ms on an H100, ten times a second, of
the 8% the service lost to its engine. An engine that `SnapshotsBeside` starts that copy and
hands a wait; the loop shows the snapshot once the next tick is stepped.

Order is kept: the held snapshot is shown before anything else happens between two ticks (the
next tick's own snapshot, a request that may change or restore the batch, a pause's), so
readers and sinks still get snapshots in tick order and never one of a state already replaced.
What a sink adds to a snapshot (the hub: entities) is read when the copy starts, at its tick.
"""

from __future__ import annotations

from collections.abc import Callable

from service.core.sim.batch import Batch, SnapshotsBeside
from service.core.sim.types import Snapshot


class BesideSnapshot:
    """At most one periodic snapshot on its way to the host (sim thread only)."""

    def __init__(
        self,
        batch: Batch,
        extend: Callable[[Snapshot], Snapshot],
        show: Callable[[Snapshot, float], None],
    ) -> None:
        """`extend`: what sinks add, at the snapshot's tick; `show(snap, now)`: publish it."""
        self._batch = batch if isinstance(batch, SnapshotsBeside) else None
        self._extend = extend
        self._show = show
        self._held: tuple[Snapshot, Callable[[], None], float] | None = None

    def start(self, now: float) -> bool:
        """Start the last tick's snapshot on its way; False: the engine cannot (take it now)."""
        got = self._batch.snapshot_beside() if self._batch is not None else None
        if got is None:
            return False
        self.finish()  # never two on their way (the caller shows each before the next)
        snap, wait = got
        self._held = (self._extend(snap), wait, now)
        return True

    def finish(self) -> int | None:
        """Show the snapshot on its way, if any, once its copy is done: its tick (else None)."""
        held, self._held = self._held, None
        if held is None:
            return None
        snap, wait, now = held
        wait()
        self._show(snap, now)
        return snap.tick
