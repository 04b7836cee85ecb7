"""Real-time pacing (service.core.sim.pace) on a clock the test moves: after a stall of up to
`MAX_LAG_S` the ticks are made up at once and no simulated time is lost; after a longer stall
the lag is given up, and the real-time factor of that window shows it (the REST guide's
"catches up to 0.1 s of lag, beyond that time is given up and the RTF shows it").

Why a hand-moved clock: only a stall of a known length shows the rule, and a real loop on a
shared machine stalls by unknown amounts. The loop is driven as SimLoop._run drives it: wait
`delay()`, tick, `ticked()`, then `RateWindow.update`.
"""

from __future__ import annotations

import pytest

from service.core.sim.pace import MAX_LAG_S, STATS_WINDOW, Cadence, RateWindow
from service.core.sim.types import Mode

DT = 1 / 120  # the default control tick
WORK = 0.002  # wall time one tick takes


class Clock:
    """Wall time that passes only when the test says so."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def run(stall_s: float, wall_s: float = 2.5, stall_at: int = 30) -> tuple[int, list[float]]:
    """Ticks done in `wall_s` of wall time with one stall of `stall_s` inside tick `stall_at`,
    and every real-time factor the rate window reported."""
    clock = Clock()
    end = clock.now + wall_s
    cadence, rate = Cadence(DT, clock), RateWindow(0, Mode.REALTIME, DT, clock)
    tick, rtfs = 0, []
    while clock.now < end:
        delay = cadence.delay()
        if delay > 0:  # the loop sleeps until the tick is due
            clock.now += delay
            continue
        clock.now += WORK + (stall_s if tick == stall_at else 0.0)
        tick += 1
        cadence.ticked()
        before = rate.stats
        rate.update(clock.now, tick, Mode.REALTIME)
        if rate.stats is not before:
            rtfs.append(rate.stats.realtime_factor)
    return tick, rtfs


def test_a_stall_within_the_catch_up_reach_loses_no_time() -> None:
    steady, steady_rtf = run(0.0)
    assert steady == pytest.approx(2.5 / DT, abs=1)
    for stall in (0.05, MAX_LAG_S - 0.01):
        ticks, rtfs = run(stall)
        assert ticks == steady, stall  # every tick the stall held up was made up
        assert rtfs[0] == pytest.approx(steady_rtf[0], abs=0.02)
    assert steady_rtf[0] == pytest.approx(1.0, abs=0.02)


def test_a_longer_stall_gives_the_time_up_and_the_rtf_shows_it() -> None:
    steady, _ = run(0.0)
    for stall in (MAX_LAG_S + 0.02, 0.5):
        ticks, rtfs = run(stall)
        lost = steady - ticks
        assert lost == pytest.approx(stall / DT, abs=2), stall  # the whole lag is given up
        # the first window (STATS_WINDOW of wall time) holds the stall: that much is missing
        assert rtfs[0] == pytest.approx((STATS_WINDOW - stall) / STATS_WINDOW, abs=0.03), stall
        assert rtfs[1] == pytest.approx(1.0, abs=0.02)  # and the next is real time again
