"""How the loop keeps time and reports it: the real-time cadence, the tick rate over a window,
and a failing tick's log line.

Why apart from the loop: each is a small rule with state of its own (a deadline, a window, the
last failure), read by the loop thread only; the loop says when, these say how much.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable

from service.core.sim.loop_types import LoopStats
from service.core.sim.types import Mode

log = logging.getLogger("armfleet.loop")

MAX_LAG_S = 0.1  # real time catches up after hiccups (a shared core paused) up to this far
# Further behind than this, the loop is on its way to giving time up: the one measure of "the
# ticks run late" (`Cadence.late`). Work that can wait gives way while it holds: the cameras'
# stream pictures wait, the commands' budget shrinks (command_share.py). Half the catch-up
# reach: a loop that only jitters by a tick or two is not held to be late, and a lag under it
# is made up (no time is lost), so nothing need give way for it.
LATE_S = MAX_LAG_S / 2
# The sim thread lets go of the GIL at every engine call, pipe read and lock wait of a tick; a
# thread busy with Python (the event loop, under a load of commands) then keeps it until it is
# asked to let go, which it is after this long (Python's default is 5 ms; the wait is one to two
# of these). A real-time tick waits for the GIL 3-4 times (the wait for its deadline, the engine
# call, the shard workers' replies, a snapshot): at 5 ms that is a 60 Hz tick's worth or more
# per tick (issue 39: 200 WebSocket clients ran the worlds at 0.24 of real time).
SWITCH_INTERVAL_S = 0.0005
STATS_WINDOW = 1.0  # seconds of wall time over which ticks/s and real-time factor are measured


def prompt_gil() -> None:
    """Ask for the GIL after `SWITCH_INTERVAL_S` in this process (never a longer wait than set)."""
    sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))


class Cadence:
    """Real time: one tick every `tick_dt` of wall time. Overrun ticks are made up at once, up
    to `MAX_LAG_S` (or one tick) behind; further behind, time is given up (the RTF shows it).

    `clock` is the wall clock (a test passes one it moves by hand, to stall the loop for a
    known time)."""

    def __init__(self, tick_dt: float, clock: Callable[[], float] = time.perf_counter) -> None:
        self.tick_dt = tick_dt
        self._clock = clock
        self._deadline = clock()

    def restart(self) -> None:
        self._deadline = self._clock()

    def delay(self) -> float:
        """Seconds until the next tick is due (<= 0: due now)."""
        return self._deadline - self._clock()

    def lag(self) -> float:
        """Seconds the schedule is behind the wall clock now (0 while on time)."""
        return max(0.0, -self.delay())

    def late(self) -> bool:
        """Behind by more than `LATE_S`: on the way to giving time up (the one lateness rule)."""
        return self.lag() > LATE_S

    def ticked(self) -> None:
        self._deadline += self.tick_dt
        now = self._clock()
        if now - self._deadline > max(self.tick_dt, MAX_LAG_S):
            self._deadline = now


class RateWindow:
    """Ticks per second and the real-time factor, measured over `STATS_WINDOW` of wall time."""

    def __init__(
        self, tick: int, mode: Mode, tick_dt: float, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self._tick_dt = tick_dt
        self._clock = clock  # the clock of `update`'s `now`
        self.stats = LoopStats(tick, mode, 0.0, 0.0)
        self._start = (clock(), tick)

    def restart(self, tick: int) -> None:
        """Measure from now (a mode change or a restore: the old window means nothing)."""
        self._start = (self._clock(), tick)

    def update(self, now: float, tick: int, mode: Mode) -> None:
        t0, tick0 = self._start
        if now - t0 < STATS_WINDOW:
            return
        rate = (tick - tick0) / (now - t0)
        self.stats = LoopStats(tick, mode, rate, rate * self._tick_dt)
        self._start = (now, tick)


class FailureLog:
    """A failing tick is logged once with its traceback, then only when its reason changes, and
    once more when ticks succeed again: a tick that fails 60 times a second never floods."""

    def __init__(self) -> None:
        self.why: str | None = None  # why the last tick failed; None while ticks succeed

    def failed(self, exc: Exception) -> None:
        why = f"{type(exc).__name__}: {exc}"
        if self.why is None:
            log.error("tick failed; the service is not ready until ticks succeed", exc_info=exc)
        elif why != self.why:
            log.error("tick still failing, now with: %s", why)
        self.why = why

    def succeeded(self) -> None:
        if self.why is not None:
            log.warning("ticks succeed again after: %s", self.why)
            self.why = None
