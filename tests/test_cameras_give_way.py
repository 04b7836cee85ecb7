"""Ticks first: while the loop runs late in realtime, the camera streams' pictures give way.

The loop says how far its realtime schedule is behind (`SimLoop.lag`), on a real engine held
up by work on its own thread; a camera clock asks for no picture while the ticks are more than
`pace.LATE_S` late (but one every `GIVE_WAY_S`), and counts the instants it gave way. The
commands' budget (command_share.py) counts late ticks by the same rule."""

from __future__ import annotations

import asyncio
import time

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
        deadline = time.monotonic() + 5
        while loop.late() and time.monotonic() < deadline:  # a loaded box may hold it up
            time.sleep(0.01)
        assert not loop.late()  # on time: behind by at most the tick in progress
        late_ticks = loop.share.late_ticks
        held = loop.call(lambda _batch: time.sleep(0.15))  # the sim thread held up 9 ticks
        time.sleep(0.1)
        lag, late = loop.lag(), loop.late()  # read while it is held
        held.result(timeout=10)
        assert lag > LATE_S and late, lag  # behind by the ticks it could not step
        # the commands' budget goes by the same rule: the ticks made up started late
        deadline = time.monotonic() + 5
        while loop.share.late_ticks == late_ticks and time.monotonic() < deadline:
            time.sleep(0.01)
        assert loop.share.late_ticks > late_ticks
        deadline = time.monotonic() + 5
        while loop.late() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert loop.lag() < LATE_S  # caught up: the missed ticks were made up
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
        self.gave_way = 0

    def ticks_late(self) -> bool:
        return self.late

    async def shoot_async(self, worlds: np.ndarray, camera: str) -> object:
        self.asked.append(worlds)
        await asyncio.sleep(3600)  # never drawn: the test looks at what was asked


def test_a_clock_asks_no_picture_while_the_ticks_are_late_but_one_a_second() -> None:
    async def run() -> tuple[int, int, int, int]:
        feed = _Feed()
        clock = CameraClock(feed, "wrist", 100.0)  # type: ignore[arg-type]
        clock.join(Reader(np.arange(4), pull=False))
        await asyncio.sleep(0.2)  # ~20 instants, all while the ticks are late (< GIVE_WAY_S)
        asked_late, gave_way = len(feed.asked), feed.gave_way
        await asyncio.sleep(GIVE_WAY_S)  # still late: one picture when a second has passed
        asked_floor = len(feed.asked)
        feed.late = False
        await asyncio.sleep(0.1)
        clock.readers.clear()
        await asyncio.sleep(0.05)
        return asked_late, gave_way, asked_floor, len(feed.asked)

    asked_late, gave_way, asked_floor, asked = asyncio.run(run())
    assert asked_late == 0 and gave_way >= 5, (asked_late, gave_way)
    assert asked_floor == 1, asked_floor
    assert asked > asked_floor  # on time again: pictures are asked (up to AHEAD in flight)
