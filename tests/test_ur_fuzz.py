"""RTDE fuzz: a few thousand odd and malformed packages (tests/ur_fuzz_cases.py, seeded) from
raw sockets to one world of a real `--ur` server (native MuJoCo, realtime), while ur_rtde's
control registers of that world are held by another client and a second world streams RTDE.

Each case is followed by a sentinel (a controller-version request) on the same connection, so
what the controller answered to the case is what came back before the sentinel's answer; the
sentinel's answer arriving also says the service did not stall. Checked: every case got an
answer it may get (the robot's answer, NOT_FOUND / IN_USE, a text message of level ERROR, or a
closed connection, as tests/ur_fuzz_cases.py says per case), setup answers carry UR's types;
the fuzzed world's joint targets, robot mode, safety mode and speed scaling are unchanged; a
second ur_rtde RTDEControlInterface to the world is refused; the other world's stream kept
its rate with no gap; the service logged no traceback. The counts by outcome are printed.
"""

from __future__ import annotations

import collections
import itertools
import re
import struct
import threading
import time
from collections.abc import Iterator

import httpx
import pytest

from tests.conftest import Server, wait_for
from tests.ur_fuzz_cases import CONTROL, Case, Connection, Fuzz, package
from tests.ur_judge import RawRtde, text_of, ur_server

rtde_control = pytest.importorskip("rtde_control")  # the `test` extra: ur-rtde==1.6.5

SEED = 40
LOG_LINE = re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d|[A-Z]+: ")  # ours, uvicorn's
CASES = 3000
WATCH_HZ = 125.0  # the other world's stream: ur_rtde's rate for a CB3, a common client rate


@pytest.fixture(scope="module")
def ur(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, list[str]]]:
    with ur_server(2, tmp_path_factory.mktemp("ur-fuzz"), mode="realtime") as pair:
        yield pair


class Watcher(threading.Thread):
    """A raw RTDE client streaming `timestamp` at WATCH_HZ: when each package came, and its
    timestamp."""

    def __init__(self, address: str) -> None:
        super().__init__(daemon=True)
        self.raw = RawRtde(address)
        self.raw.handshake()
        setup = package(ord("O"), struct.pack(">d", WATCH_HZ) + b"timestamp")
        assert self.raw.ask(setup, "O")[1:] == b"DOUBLE"
        assert self.raw.ask(package(ord("S")), "S") == b"\x01"
        self.got: list[tuple[float, float]] = []
        self.stopping = threading.Event()
        self.error: Exception | None = None

    def run(self) -> None:
        try:
            while not self.stopping.is_set():
                kind, body = self.raw.read()
                if kind == "U":
                    self.got.append((time.perf_counter(), struct.unpack(">d", body[1:9])[0]))
        except (ConnectionError, OSError) as exc:
            if not self.stopping.is_set():  # closed under it: the test reports it
                self.error = exc

    def between(self, t0: float, t1: float) -> list[tuple[float, float]]:
        return [g for g in self.got if t0 <= g[0] <= t1]

    def stop(self) -> None:
        self.stopping.set()
        self.join(timeout=5)
        self.raw.close()


def _setup_answer(pkgs: list[tuple[str, bytes]]) -> tuple[int, str] | None:
    for kind, body in pkgs:
        if kind in "OI":
            return body[0], body[1:].decode()
    return None


def outcome(raw: RawRtde, case: Case) -> tuple[str, list[tuple[str, bytes]]]:
    """Send the case and a sentinel; what the controller answered to the case, classified."""
    if case.split:
        half = len(case.data) // 2
        raw.send(case.data[:half])
        raw.send(case.data[half:] + package(ord("v")))
    else:
        raw.send(case.data + package(ord("v")))
    got: list[tuple[str, bytes]] = []
    vs = 0
    try:
        while vs <= case.requests_v:
            kind, body = raw.read()
            if kind == "v":
                vs += 1
                if vs <= case.requests_v:
                    got.append((kind, body))
            elif kind != "U":  # data packages of recipes the case started
                got.append((kind, body))
    except TimeoutError:  # no sentinel answer in the socket's 5 s: the service stalled
        return "stalled", got
    except (ConnectionError, OSError):
        return "closed", got
    setup = _setup_answer(got)
    if setup is not None:
        return ("refused" if setup[0] == 0 else "recipe"), got
    if any(kind in "VSPv" for kind, _ in got):
        return "answer", got
    if got and all(kind == "M" and body[-1] == 1 for kind, body in got):  # level ERROR
        return "error", got
    return ("silent" if not got else "other"), got


def _controller(address: str) -> tuple[int, int, float]:
    """(robot mode, safety mode, speed scaling) of the world, read over RTDE."""
    raw = RawRtde(address)
    try:
        raw.handshake()
        setup = package(ord("O"), struct.pack(">d", 10.0) + b"robot_mode,safety_mode,speed_scaling")
        assert raw.ask(setup, "O")[1:] == b"INT32,INT32,DOUBLE"
        raw.send(package(ord("S")))
        body = raw.ask(b"", "U")
        mode, safety, speed = struct.unpack(">iid", body[1:])
        return mode, safety, speed
    finally:
        raw.close()


def _targets(server: Server, world: int) -> list[float]:
    return httpx.get(f"{server.url}/v1/worlds/{world}/state", timeout=10).json()["target"]


def test_rtde_fuzz_gets_the_robots_answers_and_nobody_notices(ur) -> None:
    server, (fuzzed, other) = ur
    before = _targets(server, 0)
    assert _controller(fuzzed) == (7, 1, 1.0)
    holder = RawRtde(fuzzed)  # ur_rtde's control registers, held by another client
    holder.handshake()
    held = holder.ask(package(ord("I"), ",".join(CONTROL).encode()), "I")
    assert held[0] >= 1 and held[1:] == b"INT32" + b",DOUBLE" * 6
    watcher = Watcher(other)
    watcher.start()
    wait_for(lambda: len(watcher.got) > 10, "the other world's stream")
    b0, n0 = time.perf_counter(), len(watcher.got)  # its rate before the fuzz, on this box now
    wait_for(lambda: len(watcher.got) >= n0 + 150, "150 packages of the other world's stream")
    baseline = (len(watcher.got) - n0) / (time.perf_counter() - b0)
    fuzz = Fuzz(SEED, CONTROL)
    counts: collections.Counter[tuple[str, str]] = collections.Counter()
    wrong: list[str] = []
    raw: RawRtde | None = None
    conn = Connection()
    t0 = time.perf_counter()
    try:
        for i in range(CASES):
            if raw is None:
                raw, conn = RawRtde(fuzzed), Connection()
                raw.handshake()  # also: the service still answers after the last connection
            case = fuzz.next(conn)
            if case.last and case.allowed == {"cut"}:
                raw.send(case.data)  # a package cut short, then the client goes away
                raw.close()
                raw = None
                counts[(case.category, "cut")] += 1
                continue
            got, pkgs = outcome(raw, case)
            counts[(case.category, got)] += 1
            setup = _setup_answer(pkgs)
            if got not in case.allowed:
                wrong.append(f"case {i} {case.category}: {got} {pkgs[:2]} (may: {case.allowed})")
            elif case.types and setup is not None and case.types not in setup[1]:
                wrong.append(f"case {i} {case.category}: types {setup[1]} (want {case.types})")
            elif got == "recipe" and case.names:
                conn.inputs[setup[0]] = case.names  # type: ignore[index]
            if got == "error" and not all(text_of(b) for _, b in pkgs):
                wrong.append(f"case {i} {case.category}: an error text with no words")
            if got == "closed":
                raw.close()
                raw = None
        t1 = time.perf_counter()
        with pytest.raises(RuntimeError):  # a second control connection: ur_rtde refuses
            rtde_control.RTDEControlInterface(fuzzed)
        assert _controller(fuzzed) == (7, 1, 1.0)
    finally:
        if raw is not None:
            raw.close()
        holder.close()
        watcher.stop()
    stream = watcher.between(t0, t1)
    rate = len(stream) / (t1 - t0)
    gaps = [b[0] - a[0] for a, b in itertools.pairwise(stream)]
    by_outcome = collections.Counter()
    for (_, got), n in counts.items():
        by_outcome[got] += n
    print(
        f"\nRTDE fuzz (seed {SEED}): {sum(counts.values())} cases in {t1 - t0:.1f} s: "
        + ", ".join(f"{k} {v}" for k, v in sorted(by_outcome.items()))
        + f"; the other world's {WATCH_HZ:g} Hz stream meanwhile: {rate:.1f} packages/s "
        f"({baseline:.1f} before), "
        f"longest silence {max(gaps) * 1e3:.0f} ms"
    )
    for (category, got), n in sorted(counts.items()):
        print(f"  {category:<24} {got:<8} {n}")
    assert not wrong, "\n".join(wrong[:10])
    assert sum(counts.values()) == CASES
    assert _targets(server, 0) == before  # the fuzzed world's joint targets
    assert watcher.error is None, f"the other world's stream broke: {watcher.error}"
    slowed = f"the other world's stream slowed to {rate:.1f}/s from {baseline:.1f}/s"
    assert rate >= 0.8 * min(WATCH_HZ, baseline), slowed
    assert max(gaps) < 0.5, f"the other world's stream stopped for {max(gaps):.2f} s"
    assert all(b[1] >= a[1] for a, b in itertools.pairwise(stream))
    assert stream[-1][1] > stream[0][1]  # its ticks went on
    log = server.log()
    assert "Traceback" not in log
    # a client's bytes (text messages, names) never make lines of their own in the log
    stray = [ln for ln in log.splitlines() if not LOG_LINE.match(ln)]
    assert not stray, stray[:3]
