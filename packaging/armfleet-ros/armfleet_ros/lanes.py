"""Command lanes: the node's commands to armfleet, on a few WebSockets of their own.

armfleet gives each connection a command budget (`--command-rate`, 200/s by default), meant
for one client; the node speaks for every ROS user of every world. So commands go out on up to
16 lanes (world w on lane w mod 16), each its own connection and budget, each paced here below
that budget. A lane never has a command refused for rate: while its budget is spent, commands
for a world wait and merge (later joint values replace earlier ones, in arrival order) and go
out as one command as soon as budget returns; each message's future completes with that ack.
The control loop applies targets once per tick, so a merge within a tick changes nothing it
would have done; it only happens past the budget (e.g. one world commanded at 500 Hz).

A world has at most IN_FLIGHT commands unanswered at a time: the next waits (merging) for an
ack. armfleet takes commands in ticks first's turns (service/core/sim/command_share.py), and a
command that finds no turn within `--command-wait-s` is refused as busy, then the rest of its
connection's backlog with it for as long: on a lane, the commands of every ROS user of 16
worlds. The cap keeps a lane's backlog at armfleet to a few commands per world, and what a late
loop could not take in the meantime merges here instead of queueing there. Why 4 and not 1:
one in flight ties a world's commands to the ack's round trip (tens of ms on a loaded box).
Bench section 8's flood (1,000/s on 16 worlds, 2-core Xeon at load 3-5) merged 2,320 of 3,000
messages with 1 and 1,797 with 4, none refused either way: what merges now is mostly what the
node's executor hands over in bursts once behind, which the loop would have applied once per
tick anyway. When armfleet keeps up nothing waits.

A command's ack makes armfleet send that lane's worlds' next state frame at once, whatever the
lane's 1 Hz cadence; the node publishes it, which keeps a command's round trip short.

A command goes out from the thread that submits it (the executor's, in the subscription's
callback), on a socket made for that (line.py): through the link's event loop it waited for
another thread's turn first. Each lane has a thread of its own reading its socket (acks, the
frames it is owed: published from there at once); what waits for budget or for an ack goes
out from the thread of the ack, or of a timer when budget returns.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from typing import Any

from websockets.exceptions import InvalidHandshake

from armfleet_ros import auth
from armfleet_ros.line import LineClosed, ThreadSocket
from clients import stream
from clients.errors import CommandRejected, Unreachable
from clients.models import BatchStates, CommandAck, WsError

log = logging.getLogger("armfleet_ros")

MAX_LANES = 16
LANE_STATE_HZ = 1.0
IN_FLIGHT = 4  # a world's commands unanswered at once (the module docstring says why)


class Lane:
    """One command connection for some worlds, paced below armfleet's per-connection budget."""

    def __init__(
        self, url: str, worlds: list[int], rate: float, on_states: Callable[[BatchStates], None]
    ) -> None:
        self.url = url
        self.worlds = worlds
        self.rate = rate  # commands/s this lane may send (a margin below armfleet's)
        self.burst = max(1.0, rate / 2)
        self.on_states = on_states
        self._tokens = self.burst
        self._last = time.monotonic()
        self._ws: ThreadSocket | None = None
        self._ids = stream.CommandIds()
        self._pending: dict[int, tuple[int, list[Future]]] = {}  # id: (world, futures)
        self._in_flight: dict[int, int] = {}  # world: its commands sent, not yet answered
        self._queued: dict[int, tuple[dict[str, float], list[Future]]] = {}
        self._lock = threading.Lock()  # all of the above, from any thread
        self._timer: threading.Timer | None = None  # a pump when budget returns
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="armfleet-lane", daemon=True)
        self.merged = 0  # messages that went out merged with a later one

    def start(self) -> None:
        self._thread.start()

    @property
    def connected(self) -> bool:
        return self._ws is not None

    def stop(self) -> None:
        """Tell the lane's thread to end (`join` waits for it)."""
        self._stop.set()
        with self._lock:
            ws, timer = self._ws, self._timer
        if timer is not None:
            timer.cancel()
        if ws is not None:
            ws.close()  # the reading thread sees it closed and ends

    def join(self, timeout: float) -> None:
        self._thread.join(timeout=timeout)

    def submit(self, world: int, targets: Mapping[str, float], fut: Future) -> None:
        """Any thread: send now (from this thread), or queue (merging) until budget returns
        or the world's commands in flight are answered."""
        failed: list[Future] = []
        with self._lock:
            if self._ws is None:
                failed = [fut]
            elif world in self._queued:
                values, futs = self._queued[world]
                values.update(targets)
                futs.append(fut)
                self.merged += 1
            elif self._in_flight.get(world, 0) < IN_FLIGHT and self._take():
                failed = self._send(world, dict(targets), [fut])
            else:
                self._queued[world] = (dict(targets), [fut])
                failed = self._pump()
        self._fail(failed, "not connected to armfleet")

    def _take(self) -> bool:
        now = time.monotonic()
        self._tokens = min(self.burst, self._tokens + (now - self._last) * self.rate)
        self._last = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False

    def _send(self, world: int, targets: dict[str, float], futs: list[Future]) -> list[Future]:
        """The lock held: write the command now; the futures to fail if it could not go."""
        assert self._ws is not None
        msg_id, text = self._ids.set_targets(targets, world)
        self._pending[msg_id] = (world, futs)
        self._in_flight[world] = self._in_flight.get(world, 0) + 1
        try:
            self._ws.send(text)
        except LineClosed:
            return self._answered(msg_id)
        return []

    def _answered(self, msg_id: int | None) -> list[Future]:
        """The lock held: the futures of a command answered (or lost); its world's next may go."""
        world, futs = self._pending.pop(msg_id, (None, [])) if msg_id is not None else (None, [])
        if world is not None:
            left = self._in_flight.pop(world, 1) - 1
            if left > 0:
                self._in_flight[world] = left
        return futs

    def _pump(self) -> list[Future]:
        """The lock held: send what waits whose world may send, as budget allows; a timer for
        the rest when budget returns. The futures of what could not go (no connection)."""
        failed: list[Future] = []
        while True:
            world = next((w for w in self._queued if self._in_flight.get(w, 0) < IN_FLIGHT), None)
            if world is None:
                return failed
            if self._ws is None:
                failed += self._queued.pop(world)[1]
                continue
            if not self._take():
                if self._timer is None:
                    wait = max(0.001, (1.0 - self._tokens) / self.rate)
                    self._timer = threading.Timer(wait, self._budget_back)
                    self._timer.daemon = True
                    self._timer.start()
                return failed
            values, futs = self._queued.pop(world)
            failed += self._send(world, values, futs)

    def _budget_back(self) -> None:
        with self._lock:
            self._timer = None
            failed = self._pump()
        self._fail(failed, "not connected to armfleet")

    def _fail(self, futs: list[Future], why: str) -> None:
        for fut in futs:
            if not fut.done():
                fut.set_exception(Unreachable(None, f"{self.url}: {why}"))

    def _run(self) -> None:
        """The lane's thread: connect (again, with backoff), read acks and owed frames."""
        url = stream.ws_url(self.url, self.worlds, LANE_STATE_HZ, binary=True)
        backoff = stream.Backoff(maximum=1.0)
        while not self._stop.is_set():
            try:
                ws = ThreadSocket(url, auth.headers(), stream.MAX_SIZE)
            except (OSError, InvalidHandshake) as exc:
                log.debug("command lane: %s", exc)
            else:
                with self._lock:
                    self._ws = ws
                if self._stop.is_set():
                    ws.close()
                backoff.reset()
                while (data := ws.recv()) is not None:
                    self._frame(data)
                ws.close()
                with self._lock:
                    self._ws = None
                    lost = [f for _, futs in self._pending.values() for f in futs]
                    self._pending.clear()
                    self._in_flight.clear()
                    lost += self._pump()  # what waited behind them
                self._fail(lost, "connection lost")
            self._stop.wait(backoff.next())

    def _frame(self, data: Any) -> None:
        msg = stream.parse(data)
        if isinstance(msg, BatchStates):
            try:
                self.on_states(msg)
            except Exception:
                log.exception("publishing a state frame failed")
        elif isinstance(msg, (CommandAck, WsError)):
            with self._lock:
                futs = self._answered(msg.id)
                failed = self._pump() if self._queued else []
            self._fail(failed, "not connected to armfleet")
            for fut in futs:
                if fut.done():
                    continue
                if isinstance(msg, WsError):
                    fut.set_exception(CommandRejected(None, msg.detail))
                else:
                    fut.set_result(msg)


def lanes_for(
    url: str, worlds: list[int], rate: float, on_states: Callable[[BatchStates], None]
) -> tuple[list[Lane], dict[int, Lane]]:
    """Up to MAX_LANES lanes over `worlds`, and which lane each world's commands take."""
    n = max(1, min(MAX_LANES, len(worlds)))
    groups = [worlds[i::n] for i in range(n)]
    lanes = [Lane(url, g, rate, on_states) for g in groups if g]
    return lanes, {w: lane for lane in lanes for w in lane.worlds}
