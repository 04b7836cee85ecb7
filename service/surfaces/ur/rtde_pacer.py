"""One timer for every RTDE stream of one frequency (on the UR event loop).

Why: 32 ur_rtde programs are 64 streams at 500 Hz; a timer of its own per stream is 32,000
timer callbacks a second, each a heap push and pop and a callback of the event loop. A pacer
sends every stream of its frequency from one callback (in the order they started), keeping
its schedule on the controller's clock: the next send one period after the last one due, so a
loop that wakes a little late (a fraction of a period, every time, on a busy box) sends the
missed package at once and keeps 500 a second, where a schedule restarted from "now" made
425-478; lateness beyond `CATCH_UP_S` is given up rather than sent as a burst. A stream that starts
while its pacer runs gets its first package at the pacer's next send (at most one period
later), as a controller sends on its own clock.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Protocol

log = logging.getLogger("armfleet.ur")

CATCH_UP_S = 0.01  # at most 5 packages at 500 Hz sent back to back after a late wake-up


class Stream(Protocol):
    """One started output recipe of one connection."""

    def send_due(self, now: float) -> bool:
        """Send the stream's next package (`now`: the event loop's time of this send); False:
        the stream has ended (drop it)."""
        ...


class Pacer:
    """Every stream of one frequency, sent from one timer."""

    def __init__(self, frequency: float) -> None:
        self.period = 1.0 / frequency
        self.streams: dict[Stream, None] = {}  # an ordered set
        self._timer: asyncio.TimerHandle | None = None
        self._due = 0.0

    def add(self, stream: Stream) -> None:
        self.streams[stream] = None
        if self._timer is None:
            loop = asyncio.get_running_loop()
            self._due = loop.time()
            self._timer = loop.call_soon(self._fire)

    def remove(self, stream: Stream) -> None:
        self.streams.pop(stream, None)
        if not self.streams and self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _fire(self) -> None:
        loop = asyncio.get_running_loop()
        now = loop.time()
        for stream in list(self.streams):
            try:
                alive = stream.send_due(now)
            except Exception:  # one stream's fault never stops the others
                log.exception("RTDE stream failed; dropped")
                alive = False
            if not alive:
                self.streams.pop(stream, None)
        if not self.streams:
            self._timer = None
            return
        self._due = max(self._due + self.period, loop.time() - CATCH_UP_S)
        self._timer = loop.call_at(self._due, self._fire)


class Pacers:
    """The pacers of one event loop, one per frequency asked for."""

    def __init__(self) -> None:
        self._by_frequency: dict[float, Pacer] = {}

    def add(self, frequency: float, stream: Stream) -> None:
        pacer = self._by_frequency.get(frequency)
        if pacer is None:
            pacer = self._by_frequency[frequency] = Pacer(frequency)
        pacer.add(stream)

    def remove(self, frequency: float, stream: Stream) -> None:
        pacer = self._by_frequency.get(frequency)
        if pacer is not None:
            pacer.remove(stream)
            if not pacer.streams:
                del self._by_frequency[frequency]
