"""Who hears from the loop: snapshot sinks, tick listeners and restore listeners.

Why a class of its own: the loop says *when* (after a tick, at a snapshot, after a restore);
this says *to whom*, and keeps one listener's failure from reaching the loop or the others.
Each tuple is replaced, never mutated, so the sim thread reads it without a lock.
"""

from __future__ import annotations

import contextlib
import logging

from service.core.sim.batch import Batch
from service.core.sim.loop_types import RestoreListener, SnapshotSink, TickListener
from service.core.sim.types import BatchState, Snapshot

log = logging.getLogger("armfleet.loop")


class Listeners:
    """The loop's audience (see the module docstring); hooks run on the sim thread."""

    def __init__(self, sinks: tuple[SnapshotSink, ...] = ()) -> None:
        self.sinks: tuple[SnapshotSink, ...] = ()
        for sink in sinks:
            self.add_sink(sink)
        self._ticks: tuple[TickListener, ...] = ()
        self._restores: tuple[RestoreListener, ...] = ()

    def add_sink(self, sink: SnapshotSink) -> None:
        """Also publish snapshots to `sink` (from the next tick on). A sink subclasses
        `SnapshotSink`, whose hooks do nothing until overridden, so the loop calls them all."""
        if not isinstance(sink, SnapshotSink):
            raise TypeError(f"{sink!r} is not a SnapshotSink")
        self.sinks = (*self.sinks, sink)

    def remove_sink(self, sink: SnapshotSink) -> None:
        self.sinks = tuple(s for s in self.sinks if s is not sink)

    def add_tick_listener(self, listener: TickListener) -> None:
        """Call `listener(tick, seconds, faulted_count)` on the sim thread after every tick
        (faulted -1: the tick failed). For counters (metrics): quick, never blocking."""
        self._ticks = (*self._ticks, listener)

    def add_restore_listener(self, listener: RestoreListener) -> None:
        self._restores = (*self._restores, listener)

    def remove_restore_listener(self, listener: RestoreListener) -> None:
        self._restores = tuple(x for x in self._restores if x is not listener)

    # -- the loop's calls (sim thread) --------------------------------------------------------

    def wants_snapshot(self, now: float) -> bool:
        return any(sink.wants_snapshot(now) for sink in self.sinks)

    def extend(self, snap: Snapshot, batch: Batch) -> Snapshot:
        """The snapshot with what each sink's clients asked for besides (the hub: entities)."""
        for sink in self.sinks:
            snap = sink.extend_snapshot(snap, batch)
        return snap

    def publish(self, snap: Snapshot) -> None:
        for sink in self.sinks:
            sink.publish(snap)

    def ticked(self, batch: Batch, now: float) -> None:
        for sink in self.sinks:
            sink.on_tick(batch, now)

    def at_rest(self, batch: Batch, now: float) -> None:
        """Time stopped here (sinks may stream at a cadence of their own, which a burst of
        steps ends between)."""
        for sink in self.sinks:
            sink.at_rest(batch, now)

    def counted(self, tick: int, seconds: float, faulted: int) -> None:
        for listener in self._ticks:
            if faulted < 0:  # a failed tick: the loop is reporting it already
                with contextlib.suppress(Exception):
                    listener(tick, seconds, faulted)
                continue
            try:
                listener(tick, seconds, faulted)
            except Exception:
                log.exception("tick listener %r failed", listener)

    def restored(self, tick_before: int, state: BatchState, name: str) -> None:
        for listener in self._restores:
            try:
                listener(tick_before, state, name)
            except Exception:
                log.exception("restore listener %r failed", listener)
