"""`--lease-reset both|start|end|none`: when a leased world is sent home, per mode.

A service is built in this process from the settings (`Runtime`, native MuJoCo, one paused
world) rather than started as a server of its own per mode: the option's path is settings →
runtime → lease book → the reset command on the engine, and none of it is HTTP (the HTTP face
of leases, with the default `both`, is tests/test_leases.py against a real server; the flag
reaching the settings is tests/test_settings_names.py). Nothing is mocked: the world moves
on the real engine and a reset is read back from its state.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest

from service.runtime import Runtime
from service.settings import Settings

WORLD = 0


async def sent_home_at(mode: str, data_dir: Path) -> tuple[bool, bool]:
    """Whether the world was at home right after its lease started, and right after it ended,
    having been moved away before each."""
    settings = Settings(
        worlds=1, engine="mujoco", mode="paused", leases="optional", lease_reset=mode,
        data_dir=data_dir, save_on_exit=False,
    )  # fmt: skip
    runtime = Runtime(settings)
    await runtime.start()
    try:
        control, loop, book = runtime.control, runtime.loop, runtime.leases
        assert control is not None and loop is not None and book is not None, runtime.error
        home = loop.batch.home_target.copy()  # (7,): the same for every world

        def move_away() -> None:  # a new target, and simulated time since the last reset
            control.increment(WORLD, {"elbow_joint": 0.3}, "test")
            loop.step(2).result(timeout=30)

        def at_home() -> bool:
            snap = loop.fresh_snapshot([WORLD]).result(timeout=30)
            fresh = snap.sim_time[WORLD] == 0.0
            assert fresh == np.array_equal(snap.target[WORLD], home)  # a reset does both
            return bool(fresh)

        move_away()
        assert not at_home()
        lease, _token = book.grant(worlds=[WORLD], ttl_s=60, label=mode)
        at_start = at_home()
        move_away()
        book.release(lease.id)
        at_end = at_home()
    finally:
        runtime.stop()
    return at_start, at_end


@pytest.mark.parametrize(
    ("mode", "start", "end"),
    [("both", True, True), ("start", True, False), ("end", False, True), ("none", False, False)],
)
def test_the_option_says_when_a_leased_world_is_sent_home(
    mode: str, start: bool, end: bool, tmp_path: Path
) -> None:
    assert asyncio.run(sent_home_at(mode, tmp_path)) == (start, end)
