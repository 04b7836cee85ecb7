"""Snapshots and a recording's start answer while every parameter of every world is rewritten
(issue 38 item 7), on a 16-world server of the default engine (MuJoCo Warp on the CPU).

Both need one tick boundary: the state they save is one tick's. On a CPU, a parameter write
that made a Model field per world captured the tick's graph again, on the sim thread, once per
field: seconds each, so a fuzz run's first payload or mass writes held every snapshot and
recording start behind them for over 10 s. Every field a parameter may write is now per world
from the build, and no write captures again; the server's own counter of capture time,
`armfleet_engine_capture_seconds_total`, shows that no request waited behind one. Timing is not
asserted (bench measures speed): every request answers, and the counter does not move.
"""

from __future__ import annotations

import concurrent.futures
from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest

from clients.testing import Server, serve
from tests.conftest import metric

NWORLD = 16
SNAPSHOTS = 8


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    with serve(
        worlds=NWORLD, extra_args=("--engine", "warp"), log_dir=tmp_path_factory.mktemp("busy")
    ) as srv:
        yield srv


def middle(param: dict[str, Any]) -> float | list[float]:
    """A value inside the parameter's range (a list for payload)."""
    values = [(lo + hi) / 2 for lo, hi in zip(param["lower"], param["upper"], strict=True)]
    return values if len(values) > 1 else values[0]


def test_snapshots_and_a_recording_start_answer_while_every_parameter_is_written(
    fleet: Server,
) -> None:
    with httpx.Client(base_url=fleet.url, timeout=120) as http:
        assert http.get("/v1/info").json()["captured"]  # the default engine captures its tick
        table = http.get("/v1/params").json()["params"]
        before = metric(http, "armfleet_engine_capture_seconds_total")
        assert before > 0  # the build's capture is counted

        # Every parameter of every world, one request per parameter (each one a fresh field),
        # the payload through its own route too, a randomisation of masses and frictions;
        # beside them a recording of every world and SNAPSHOTS snapshots, all at once.
        def every_world(p: dict[str, Any]) -> httpx.Response:
            items = [{"world": w, "params": {p["name"]: middle(p)}} for w in range(NWORLD)]
            return http.post("/v1/params", json={"writes": items})

        writes: list[Callable[[], httpx.Response]] = [lambda p=p: every_world(p) for p in table]
        writes.append(
            lambda: http.put("/v1/worlds/3/payload", json={"mass": 2.0, "cog": [0, 0, 0.1]})
        )
        spec = {"params": {"cube.mass": [0.1, 0.4], "cube.friction": [0.5, 1.0]}}
        writes.append(
            lambda: http.post("/v1/randomize", json={"seed": 5, "spec": spec, "worlds": [0]})
        )
        persisted: list[Callable[[], httpx.Response]] = [
            lambda: http.post("/v1/recordings", json={"name": "run1", "rate": 30, "worlds": "0-15"})
        ]
        persisted += [
            lambda i=i: http.post("/v1/snapshots", json={"name": f"busy{i}"})
            for i in range(SNAPSHOTS)
        ]
        # interleaved, so that the snapshots and the recording go out among the writes
        calls = [c for i in range(len(writes)) for c in (writes[i], *persisted[i : i + 1])]
        with concurrent.futures.ThreadPoolExecutor(max_workers=8) as pool:
            replies = list(pool.map(lambda call: call(), calls))
        for reply in replies:
            assert reply.status_code in (200, 201), (reply.request.url, reply.text)
        names = {s["name"] for s in http.get("/v1/snapshots").json()}
        assert {f"busy{i}" for i in range(SNAPSHOTS)} <= names
        recording = http.get("/v1/recordings/current").json()
        assert recording["active"] and recording["worlds"] == list(range(NWORLD))
        # no write captured the tick again: nothing waited behind a capture
        assert metric(http, "armfleet_engine_capture_seconds_total") == before
        # the values are in effect (the writes were not dropped to get there)
        got = http.get("/v1/worlds/7/params").json()["params"]
        for p in table:
            assert got[p["name"]] == pytest.approx(middle(p), rel=1e-5, abs=1e-4)
        assert http.delete("/v1/recordings/current").status_code == 200
