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
from typing import Any, TypeVar

from service.core.sim.batch import Batch
from service.core.sim.types import Snapshot

T = TypeVar("T")
Request = tuple[Callable[[Batch], Any], concurrent.futures.Future[Any]]


class Waiters:
    """The queues of requests, step futures and snapshot readers (the loop's lock guards them)."""

    def __init__(self) -> None:
        self._requests: list[Request] = []
        self._steps: list[tuple[int, concurrent.futures.Future[int]]] = []
        self._readers: list[tuple[int, concurrent.futures.Future[Snapshot]]] = []

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

    # -- `step`: a future per goal tick -------------------------------------------------------

    def add_step(self, goal: int) -> concurrent.futures.Future[int]:
        fut: concurrent.futures.Future[int] = concurrent.futures.Future()
        self._steps.append((goal, fut))
        return fut

    def steps_reached(self, tick: int) -> list[concurrent.futures.Future[int]]:
        """The step futures whose goal `tick` reaches, taken out of the queue."""
        done = [f for g, f in self._steps if g <= tick]
        self._steps = [(g, f) for g, f in self._steps if g > tick]
        return done

    def take_steps(self) -> list[concurrent.futures.Future[int]]:
        """Every step future (a restore completes them at the restored tick)."""
        steps, self._steps = [f for _, f in self._steps], []
        return steps

    # -- readers of a snapshot of at least some tick ------------------------------------------

    def add_reader(self, need: int) -> concurrent.futures.Future[Snapshot]:
        fut: concurrent.futures.Future[Snapshot] = concurrent.futures.Future()
        self._readers.append((need, fut))
        return fut

    @property
    def readers_waiting(self) -> bool:
        return bool(self._readers)

    def readers_served_by(self, tick: int) -> list[concurrent.futures.Future[Snapshot]]:
        """The readers a snapshot of `tick` satisfies, taken out of the queue."""
        ready = [f for need, f in self._readers if need <= tick]
        self._readers = [(n, f) for n, f in self._readers if n > tick]
        return ready

    def take_readers(self) -> list[concurrent.futures.Future[Snapshot]]:
        """Every reader (time stands still, or a restore replaced the timeline)."""
        readers, self._readers = [f for _, f in self._readers], []
        return readers

    def cancel_all(self) -> None:
        """The loop stopped: nobody will serve what still waits (call without the lock)."""
        for fut in (*self.take_steps(), *self.take_readers()):
            fut.cancel()
