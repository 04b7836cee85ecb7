"""What the simulation loop hands out and takes in: command results, stats, sinks, listeners.

Split from loop.py so that the loop module is the loop; everything here is plain data or a
small helper on a future, used by the loop and by whoever talks to it.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from service.core.sim.batch import Batch
from service.core.sim.types import BatchState, Mode, Snapshot

T = TypeVar("T")
# Called on the sim thread after a restore: (tick before, the state restored, its name).
RestoreListener = Callable[[int, BatchState, str], None]
TickListener = Callable[[int, float, int], None]  # (tick, seconds, faulted)


@dataclass(frozen=True)
class CommandResult:
    """Reply to a target command: the world's target row after it, what clamped, when it applies."""

    world: int
    target: np.ndarray
    clamped: list[str]
    tick: int


@dataclass(frozen=True)
class LoopStats:
    tick: int
    mode: Mode
    ticks_per_s: float
    realtime_factor: float


class SnapshotSink:
    """Where snapshots go (the stream hub, the ROS 2 bridge, the recorder, ...).

    Every method runs on the sim thread between ticks (`on_tick` after every tick, for sinks
    that take what they need from the batch themselves): they must be quick and hand any real
    work (serialising, sending, writing) to a thread or event loop of their own.
    """

    def wants_snapshot(self, now: float) -> bool:
        return False

    def publish(self, snapshot: Snapshot) -> None: ...

    def on_tick(self, batch: Batch, now: float) -> None: ...

    def at_rest(self, batch: Batch, now: float) -> None:
        """Time stopped at the batch's tick (paused: the last tick of a step burst, or where a
        pause found it): no later tick will carry its state, so show it now."""

    def extend_snapshot(self, snap: Snapshot, batch: Batch) -> Snapshot:
        """The snapshot about to be published, with what this sink's clients asked for besides
        (the hub: entities, while a client asks), read from `batch` at the snapshot's tick."""
        return snap


def resolve(fut: concurrent.futures.Future[Snapshot], snap: Snapshot) -> None:
    if not fut.done():  # a reader that gave up may have cancelled it
        with contextlib.suppress(concurrent.futures.InvalidStateError):
            fut.set_result(snap)


def run_request(fn: Callable[[Batch], T], fut: concurrent.futures.Future[T], batch: Batch) -> None:
    if not fut.set_running_or_notify_cancel():
        return
    try:
        fut.set_result(fn(batch))
    except BaseException as exc:  # handed to whoever waits on the future
        fut.set_exception(exc)
