"""What other threads wait on from the sim thread: work between two ticks, a tick reached by
`step`, a snapshot of at least some tick (read-your-writes).

Why a class of its own: the loop decides *when* each of these is due (it knows the tick, the
mode and the step goal); this class only keeps the queues and hands over what is due, so the
loop's module is the loop and the bookkeeping of futures is written once. Not thread-safe by
itself: every method runs with the loop's lock held, except where a docstring says otherwise.
"""

from __future__ import annotations

import concurrent.futures
from collections.abc import Callable
from typing import Any, Generic, TypeVar

from service.core.sim.batch import Batch
from service.core.sim.types import Snapshot

T = TypeVar("T")
Request = tuple[Callable[[Batch], Any], concurrent.futures.Future[Any]]


class TickQueue(Generic[T]):
    """Futures each waiting for some tick: `step` goals, or readers of a snapshot of at least
    a tick. What a tick reaches is taken out in one pass."""

    def __init__(self) -> None:
        self._waiting: list[tuple[int, concurrent.futures.Future[T]]] = []

    def __bool__(self) -> bool:
        return bool(self._waiting)

    def add(self, tick: int) -> concurrent.futures.Future[T]:
        fut: concurrent.futures.Future[T] = concurrent.futures.Future()
        self._waiting.append((tick, fut))
        return fut

    def reached(self, tick: int) -> list[concurrent.futures.Future[T]]:
        """The futures waiting for `tick` or earlier, taken out of the queue."""
        done = [f for need, f in self._waiting if need <= tick]
        self._waiting = [(need, f) for need, f in self._waiting if need > tick]
        return done

    def take(self) -> list[concurrent.futures.Future[T]]:
        """Every future, whatever its tick."""
        taken, self._waiting = [f for _, f in self._waiting], []
        return taken


class Waiters:
    """The queues of requests, step futures and snapshot readers (the loop's lock guards them)."""

    def __init__(self) -> None:
        self._requests: list[Request] = []
        self.steps: TickQueue[int] = TickQueue()  # `step`: a future per goal tick
        self.readers: TickQueue[Snapshot] = TickQueue()  # a snapshot of at least a tick

    # -- work for the sim thread between two ticks --------------------------------------------

    def add_request(self, fn: Callable[[Batch], T]) -> concurrent.futures.Future[T]:
        fut: concurrent.futures.Future[T] = concurrent.futures.Future()
        self._requests.append((fn, fut))
        return fut

    @property
    def requests_waiting(self) -> bool:
        return bool(self._requests)

    def take_requests(self) -> list[Request]:
        requests, self._requests = self._requests, []
        return requests

    def cancel_all(self) -> None:
        """The loop stopped: nobody will serve what still waits (call without the lock)."""
        for fut in (*self.steps.take(), *self.readers.take()):
            fut.cancel()
