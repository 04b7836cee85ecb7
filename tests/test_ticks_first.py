"""Ticks first under load: the command budget beside real-time ticks, and the refusal path.

The budget's rule alone (service/core/sim/command_share.py), then a real server over real
sockets: a client over its command rate gets error replies naming the limit, counted in
/metrics, while another client's commands are acked in order, its final target the sum of
what was acked. Speed itself is measured in `armfleet bench --section 31`, not here.
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
import threading
import time

import httpx
import pytest
from conftest import running_server
from websockets.sync.client import connect

from service.core.sim import command_share
from service.core.sim.command_share import (
    FLOOR_SHARE,
    REQUESTS_NICE,
    CommandShare,
    cpu_now,
    turn,
)
from service.core.sim.loop import SimLoop
from service.core.sim.pace import SWITCH_INTERVAL_S
from service.core.sim.settings import SimSettings
from service.engines.choice import build_batch
from service.engines.settings import EngineSettings

DT = 1 / 60


class Clock:
    """The share's clock, moved by hand: the budget's rule without the box's timing."""

    def __init__(self) -> None:
        self.now = 100.0

    def monotonic(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch) -> Clock:
    fake = Clock()
    monkeypatch.setattr(command_share, "time", fake)
    return fake


def test_late_ticks_shrink_the_budget_to_the_floor_and_on_time_ticks_grow_it_back(clock):
    share = CommandShare(DT)
    assert share.budget_s == pytest.approx(DT)
    for _ in range(40):
        clock.now += DT
        share.ticked(late=True)
    assert share.budget_s == pytest.approx(FLOOR_SHARE * DT)
    assert share.late_ticks == 40
    clock.now += DT
    share.ticked(late=False)
    assert share.budget_s > FLOOR_SHARE * DT and share.late_ticks == 40
    for _ in range(100):
        clock.now += DT
        share.ticked(late=False)
    assert share.budget_s == pytest.approx(DT)


def test_slow_ticks_leave_commands_a_share_of_the_wall_time(clock):
    """Ticks late for reasons of their own (a box shared with others): commands still move."""
    share = CommandShare(DT)
    for _ in range(40):
        clock.now += 0.2  # a tick every 0.2 s instead of every 1/60 s
        share.ticked(late=True)
    assert share.budget_s == pytest.approx(FLOOR_SHARE * 0.2)


def test_a_spent_budget_waits_for_the_next_tick_only_in_real_time(clock):
    share = CommandShare(DT)
    assert share.may_run()  # not real time yet: nothing waits
    share.set_active(True)
    clock.now += DT
    share.ticked(late=True)  # budget halved, a new tick
    assert share.may_run()
    share.spent(share.budget_s)
    assert not share.may_run()
    clock.now += DT
    share.ticked(late=False)  # the next tick: a fresh budget
    assert share.may_run()
    share.spent(10 * DT)
    assert not share.may_run()
    share.set_active(False)  # paused or fast: commands never wait for ticks
    assert share.may_run()
    share.set_active(True)
    share.enabled = False  # --no-ticks-first
    assert share.may_run()


def test_a_command_is_charged_the_cpu_it_used_not_the_wall_time_others_took():
    """What a command costs the ticks is the core and the GIL it held: time its thread spent
    waiting (for the GIL, or for a core another process had) is not charged to it."""
    t0 = cpu_now()
    time.sleep(0.05)  # its thread waits: 50 ms of wall time, next to no CPU
    waited = cpu_now() - t0
    t0 = cpu_now()
    end = time.perf_counter() + 0.02
    while time.perf_counter() < end:  # its thread works: 20 ms of CPU (more, descheduled)
        pass
    worked = cpu_now() - t0
    assert waited < 0.005
    assert 0 < worked <= 0.025


def _spent_share(max_wait_s: float) -> CommandShare:
    share = CommandShare(DT, max_wait_s=max_wait_s)
    share.set_active(True)
    share.ticked(False)
    share.may_run()
    share.spent(DT)  # this tick's budget used
    return share


def test_a_waiting_command_runs_at_the_next_tick():
    share = _spent_share(max_wait_s=30.0)

    async def main() -> bool:
        waiting = asyncio.ensure_future(turn(share))
        await asyncio.sleep(0)  # it waits on the tick's future
        assert not waiting.done()
        threading.Thread(target=share.ticked, args=(False,)).start()  # the sim thread's tick
        return await waiting

    assert asyncio.run(main()) is True
    assert share.waits == 1 and share.busy == 0


def test_a_command_with_no_turn_within_the_longest_wait_is_refused_as_busy():
    share = _spent_share(max_wait_s=0.05)  # and no tick comes
    assert asyncio.run(turn(share)) is False
    assert share.busy == 1
    assert "busy: no turn within 0.05 s beside the ticks (--command-wait-s)" in share.busy_detail
    assert asyncio.run(turn(share, wait=False)) is False  # right after: refused at once
    assert share.busy == 2 and share.waits == 1


def test_a_running_loop_gets_the_gil_back_within_half_a_millisecond_of_asking():
    """Python's default 5 ms is what a thread busy with Python (the event loop under commands)
    may keep the GIL from the sim thread each time the sim thread let go of it (an engine call,
    a pipe read, the wait for the next tick): several times a tick. A loop sets 0.5 ms."""
    batch = build_batch(EngineSettings(kind="mujoco", shards=1), SimSettings(worlds=1))
    before = sys.getswitchinterval()
    sys.setswitchinterval(0.005)  # Python's default; an earlier test may have lowered it
    loop = SimLoop(batch)
    try:
        loop.start()
        assert sys.getswitchinterval() == pytest.approx(SWITCH_INTERVAL_S)
    finally:
        loop.stop()
        batch.close()
        sys.setswitchinterval(min(before, sys.getswitchinterval()))


# --------------------------------------------------------------------------- a real server

RATE, BURST = 0.1, 4  # a token every 10 s: what is sent at once beyond the burst is refused
LIMIT = f"rate: over {RATE:g} commands/s (bursts of {BURST}); slow down"  # what a refusal says


@pytest.fixture(scope="module")
def limited(tmp_path_factory):
    extra = ("--engine", "mujoco", "--command-rate", str(RATE), "--command-burst", str(BURST))
    with running_server(tmp_path_factory.mktemp("ticks_first"), worlds=2, extra=extra) as srv:
        yield srv


def _press(ws, msg_id, delta=0.01) -> None:
    ws.send(json.dumps({"op": "increment", "joint": "elbow_joint", "delta": delta, "id": msg_id}))


def _replies(ws, n: int) -> list[dict]:
    out: list[dict] = []
    while len(out) < n:
        msg = json.loads(ws.recv(timeout=10))
        if msg["op"] in ("ack", "error"):
            out.append(msg)
    return out


def _refused(url: str, source: str = "ws") -> float:
    text = httpx.get(f"{url}/metrics").text
    total = 0.0
    for line in text.splitlines():
        series = line.startswith("armfleet_commands_total{") and f'source="{source}"' in line
        if series and 'result="refused"' in line:
            total += float(line.rpartition(" ")[2])
    return total


def test_a_client_over_its_rate_is_refused_by_name_counted_and_alone(limited):
    before = _refused(limited.url)
    elbow = [j["name"] for j in httpx.get(f"{limited.url}/v1/info").json()["joints"]].index(
        "elbow_joint"
    )
    start = httpx.get(f"{limited.url}/v1/worlds/1/state").json()["target"][elbow]
    with (
        connect(f"{limited.ws_url}/v1/ws/worlds/0?rate=1") as greedy,
        connect(f"{limited.ws_url}/v1/ws/worlds/1?rate=1") as calm,
    ):
        for i in range(2 * BURST):  # at once: the burst, then over the rate
            _press(greedy, f"g{i}")
        greedy_replies = _replies(greedy, 2 * BURST)
        calm_replies = []
        for i in range(BURST):  # within its own limit: never refused for the other's sake
            _press(calm, f"c{i}")
            calm_replies += _replies(calm, 1)
    ids = [r["id"] for r in greedy_replies]
    assert ids == [f"g{i}" for i in range(2 * BURST)]  # one reply each, in the order sent
    acked = [r for r in greedy_replies if r["op"] == "ack"]
    errors = [r for r in greedy_replies if r["op"] == "error"]
    assert [r["id"] for r in acked] == [f"g{i}" for i in range(len(acked))]  # a prefix
    assert len(acked) >= BURST and errors
    for r in errors:
        assert r["detail"] == LIMIT
    assert _refused(limited.url) - before == len(errors)
    assert [r["op"] for r in calm_replies] == ["ack"] * BURST
    assert [r["id"] for r in calm_replies] == [f"c{i}" for i in range(BURST)]
    ticks = [r["tick"] for r in calm_replies]
    assert ticks == sorted(ticks)
    end = httpx.get(f"{limited.url}/v1/worlds/1/state").json()["target"][elbow]
    assert end == pytest.approx(start + 0.01 * BURST, abs=1e-9)


def test_an_http_connection_over_its_rate_gets_429_naming_the_limit(limited):
    before = _refused(limited.url, "http")
    press = {"joint": "elbow_joint", "delta": 0.01}
    with httpx.Client(base_url=limited.url, timeout=10) as greedy:  # one keep-alive connection
        answers = [greedy.post("/v1/worlds/0/increments", json=press) for _ in range(2 * BURST)]
        with httpx.Client(base_url=limited.url, timeout=10) as calm:  # another connection
            assert calm.post("/v1/worlds/1/increments", json=press).status_code == 200
    codes = [r.status_code for r in answers]
    first = codes.index(429)
    assert first >= BURST and set(codes[:first]) == {200}  # its burst, then refused
    ticks = [r.json()["tick"] for r in answers[:first]]
    assert ticks == sorted(ticks)
    refused = [r for r in answers if r.status_code == 429]
    for r in refused:
        assert r.json()["detail"] == LIMIT
        assert r.headers["retry-after"] == "1"
    assert _refused(limited.url, "http") - before == len(refused)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="priority is per thread on Linux")
def test_the_event_loop_thread_gives_the_cores_to_the_ticks_first(limited):
    """Under contention the scheduler favours the ticks' threads: the serving process's event
    loop (its main thread) runs REQUESTS_NICE below the priority it started with, the sim
    thread (started before it lowered itself) at that priority still."""
    pid = limited.process.pid
    base = os.getpriority(os.PRIO_PROCESS, os.getpid())  # the server started with ours
    nice = {
        int(t): os.getpriority(os.PRIO_PROCESS, int(t)) for t in os.listdir(f"/proc/{pid}/task")
    }
    assert nice.pop(pid) == min(19, base + REQUESTS_NICE)
    assert base in nice.values()
