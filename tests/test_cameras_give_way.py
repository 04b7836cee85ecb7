"""Ticks first: while the loop runs late in realtime, the camera streams' pictures give way.

The loop says how far its realtime schedule is behind (`SimLoop.lag`), on a real engine held
up by work on its own thread; a camera clock asks for no picture while the ticks are more than
`pace.LATE_S` late (but one every `GIVE_WAY_S`), and counts the instants it gave way. The
commands' budget (command_share.py) counts late ticks by the same rule."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable

import numpy as np

from service.core.cameras.clock import GIVE_WAY_S, CameraClock, Reader
from service.core.sim.loop import SimLoop
from service.core.sim.pace import LATE_S
from service.core.sim.settings import SimSettings
from service.core.sim.types import Mode
from service.engines.choice import build_batch
from service.engines.settings import EngineSettings


def test_lag_says_how_far_realtime_is_behind_and_comes_back_to_zero() -> None:
    batch = build_batch(EngineSettings(kind="mujoco", shards=1), SimSettings(worlds=2))
    loop = SimLoop(batch, Mode.REALTIME)
    loop.start()
    try:
        deadline = time.monotonic() + 30
        while loop.late() and time.monotonic() < deadline:  # a loaded box may hold it up
            time.sleep(0.01)
        assert not loop.late()  # on time: behind by at most the tick in progress
        late_ticks = loop.share.late_ticks
        # The sim thread is held until the lag has been read (an Event, not a fixed hold: a
        # test thread that overslept a 0.15 s hold on a loaded box read the lag after the loop
        # had caught up). Its schedule was due at most a tick after it stopped, so the lag read
        # at `read` is at least `read - stopped - DT`: `stopped` taken after the sim thread
        # said it stopped, `read` before the lag is read (each on its safe side).
        holding, release = threading.Event(), threading.Event()

        def hold(_batch: object) -> None:
            holding.set()
            release.wait(30)

        held = loop.call(hold)
        try:
            assert holding.wait(30), "the sim thread never took the call"
            stopped = time.perf_counter()
            time.sleep(0.08)  # over LATE_S + a tick, within MAX_LAG_S on a quiet box
            read = time.perf_counter()
            lag, late = loop.lag(), loop.late()  # read while it is held
        finally:
            release.set()
        held.result(timeout=30)
        assert lag >= read - stopped - batch.tick_dt, (lag, read - stopped)
        assert lag > LATE_S and late, lag  # behind by the ticks it could not step
        # the commands' budget goes by the same rule: the ticks made up started late
        deadline = time.monotonic() + 30
        while loop.share.late_ticks == late_ticks and time.monotonic() < deadline:
            time.sleep(0.01)
        assert loop.share.late_ticks > late_ticks
        deadline = time.monotonic() + 30
        while loop.late() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert loop.lag() < LATE_S  # caught up: the missed ticks made up (or, held past
        # MAX_LAG_S by a loaded box, given up)
        loop.set_mode(Mode.FAST)
        assert loop.lag() == 0.0  # no schedule to be behind of
    finally:
        loop.stop()
        batch.close()


class _Feed:
    """What a clock reads of its camera feed: the ticks' lateness, and pictures on request
    (the clock's own logic under test; the real feed is exercised by test_camera_stream)."""

    def __init__(self) -> None:
        self.late = True
        self.asked: list[np.ndarray] = []
        self.asked_at: list[float] = []  # when each ask reached the feed (after the decision)
        self.gave_way = 0

    def ticks_late(self) -> bool:
        return self.late

    async def shoot_async(self, worlds: np.ndarray, camera: str) -> object:
        self.asked.append(worlds)
        self.asked_at.append(time.monotonic())
        await asyncio.sleep(3600)  # never drawn: the test looks at what was asked


async def _until(pred: Callable[[], bool], what: str, timeout: float = 30) -> None:
    deadline = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < deadline, f"timed out after {timeout} s waiting for {what}"
        await asyncio.sleep(0.01)


def test_a_clock_asks_no_picture_while_the_ticks_are_late_but_one_a_second() -> None:
    """Measured so that a loaded box giving the event loop few turns cannot fail it: no fixed
    windows counting instants, but each bound from timestamps on its safe side (`start` before
    the clock exists; an ask's time after the clock decided it)."""

    async def run() -> None:
        feed = _Feed()
        start = time.monotonic()
        clock = CameraClock(feed, "wrist", 100.0)  # type: ignore[arg-type]
        clock.join(Reader(np.arange(4), pull=False))
        # late all along: the instants of the first second give way (counted), then one
        # picture once a second has passed
        await _until(lambda: bool(feed.asked), "the one picture a second while late")
        assert feed.asked_at[0] - start >= GIVE_WAY_S, feed.asked_at[0] - start
        assert feed.gave_way >= 1  # ~100 on a quiet box; each instant a reader was ready
        await asyncio.sleep(0.3)  # still late
        asked, elapsed = len(feed.asked), time.monotonic() - start
        assert asked <= elapsed / GIVE_WAY_S, (asked, elapsed)  # at most one a second
        feed.late = False  # on time again: pictures are asked (up to AHEAD in flight)
        await _until(lambda: len(feed.asked) > asked, "a picture asked on time")
        clock.readers.clear()
        await asyncio.sleep(0.05)

    asyncio.run(run())
