"""A batch subscriber sees where time stopped. Paused, a burst of steps (`POST /v1/sim/step`)
ends between two frames of a slow stream (1 Hz here), and no later tick comes to carry the
state: the stream must still send the tick the step's reply names, in every format, binary
included (packed frames, service/core/frames.py). Likewise a pause from realtime."""

from __future__ import annotations

import time
from collections.abc import Iterator

import httpx
import pytest
from websockets.sync.client import ClientConnection, connect

from clients import _stream
from tests.conftest import Server, serve


@pytest.fixture(scope="module")
def paused(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    args = ["--engine", "mujoco"]
    with serve(worlds=3, mode="paused", extra_args=args, log_dir=tmp_path_factory.mktemp("s")) as s:
        yield s


def newest_tick(ws: ClientConnection, wait_for: int, within: float = 5.0) -> int:
    """Read frames until one of tick `wait_for` (or `within` seconds pass): the last tick read."""
    tick, end = -1, time.monotonic() + within
    while tick != wait_for and time.monotonic() < end:
        try:
            msg = _stream.parse(ws.recv(timeout=max(0.01, end - time.monotonic())))
        except TimeoutError:
            break
        if msg is not None and hasattr(msg, "tick") and hasattr(msg, "worlds"):
            tick = msg.tick
    return tick


@pytest.mark.parametrize("fmt", ["binary", "json"])
def test_a_burst_of_steps_ends_with_a_frame_of_its_last_tick(paused: Server, fmt: str) -> None:
    query = "worlds=0-2&rate=1" + ("&format=binary" if fmt == "binary" else "")
    with (
        connect(f"{paused.ws_url}/v1/ws?{query}", max_size=None) as ws,
        httpx.Client(base_url=paused.url, timeout=30) as http,
    ):
        first = _stream.parse(ws.recv(timeout=10))
        assert first is not None and getattr(first, "tick", None) is not None
        for _ in range(3):
            tick = http.post("/v1/sim/step", json={"ticks": 25}).json()["tick"]
            assert newest_tick(ws, tick) == tick
            time.sleep(0.4)  # the next burst falls on the 1 Hz cadence, or between


def test_a_pause_from_realtime_ends_with_a_frame_of_the_tick_it_stopped_at(
    paused: Server,
) -> None:
    with (
        connect(f"{paused.ws_url}/v1/ws?worlds=0-2&rate=1&format=binary") as ws,
        httpx.Client(base_url=paused.url, timeout=30) as http,
    ):
        ws.recv(timeout=10)
        http.post("/v1/sim/mode", json={"mode": "realtime"})
        time.sleep(0.3)
        tick = http.post("/v1/sim/pause").json()["tick"]
        assert newest_tick(ws, tick) == tick
