"""Subscription cadence: frames at the asked rate, plus the one an acked command is owed."""

from __future__ import annotations

import numpy as np

from service.core.sim.types import Poses, Snapshot
from service.core.streams.formats import FrameFormat
from service.core.streams.hub import Subscription


def snap(tick: int) -> Snapshot:
    z = np.zeros((1, 7))
    return Snapshot(
        tick=tick,
        sim_time=np.zeros(1),
        position=z,
        velocity=z,
        effort=z,
        target=z,
        faults=np.zeros(1, dtype=np.int64),
        flange=Poses(np.zeros((1, 3)), np.zeros((1, 4))),
        bodies=Poses(np.zeros((1, 1, 3), np.float32), np.zeros((1, 1, 4), np.float32)),
    )


def test_a_slow_stream_takes_frames_only_at_its_rate():
    sub = Subscription(np.array([0]), 1.0, FrameFormat.single(), lambda s: b"")
    assert sub.wants(snap(1), now=10.0)
    sub.offer(snap(1), now=10.0)
    assert not sub.wants(snap(2), now=10.5)
    assert sub.wants(snap(60), now=11.0)


def test_an_owed_frame_goes_out_at_once_without_moving_the_cadence():
    sub = Subscription(np.array([0]), 1.0, FrameFormat.single(), lambda s: b"")
    sub.offer(snap(1), now=10.0)  # next regular frame at 11.0
    sub.owe(5)
    assert not sub.wants(snap(4), now=10.05)  # before the command's tick: nothing owed yet
    assert sub.wants(snap(5), now=10.1)
    sub.offer(snap(5), now=10.1)
    assert sub.owed_tick is None and sub.latest is not None and sub.latest.tick == 5
    assert not sub.wants(snap(6), now=10.2)  # paid: back to the cadence ...
    assert sub.wants(snap(60), now=11.0)  # ... which the owed frame did not shift
    sub.owe(70)
    sub.owe(65)  # two commands: the earlier tick is owed first
    assert sub.owed_tick == 65
