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
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from typing import Any

from websockets.asyncio.client import connect

from armfleet_ros import auth
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
        self._ws: Any = None
        self._ids = stream.CommandIds()
        self._pending: dict[int, tuple[int, list[Future]]] = {}  # id: (world, futures)
        self._in_flight: dict[int, int] = {}  # world: its commands sent, not yet answered
        self._queued: dict[int, tuple[dict[str, float], list[Future]]] = {}
        self._wake: asyncio.Event | None = None
        self.merged = 0  # messages that went out merged with a later one

    def submit(self, world: int, targets: Mapping[str, float], fut: Future) -> None:
        """On the link's event loop: send now, or queue (merging) until budget returns."""
        if self._ws is None:
            fut.set_exception(Unreachable(None, f"{self.url}: not connected to armfleet"))
            return
        if world in self._queued:
            values, futs = self._queued[world]
            values.update(targets)
            futs.append(fut)
            self.merged += 1
            return
        if self._in_flight.get(world, 0) < IN_FLIGHT and self._take():
            self._send(world, dict(targets), [fut])
        else:
            self._queued[world] = (dict(targets), [fut])
            assert self._wake is not None
            self._wake.set()

    def _take(self) -> bool:
        now = time.monotonic()
        self._tokens = min(self.burst, self._tokens + (now - self._last) * self.rate)
        self._last = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False

    def _send(self, world: int, targets: dict[str, float], futs: list[Future]) -> None:
        msg_id, text = self._ids.set_targets(targets, world)
        self._pending[msg_id] = (world, futs)
        self._in_flight[world] = self._in_flight.get(world, 0) + 1
        task = asyncio.ensure_future(self._ws.send(text))
        task.add_done_callback(lambda t: self._sent(t, msg_id))

    def _sent(self, task: asyncio.Task, msg_id: int) -> None:
        if task.cancelled() or task.exception() is not None:
            self._fail(self._answered(msg_id), "connection lost")

    def _answered(self, msg_id: int | None) -> list[Future]:
        """The futures of a command answered (or lost); its world's next command may go."""
        world, futs = self._pending.pop(msg_id, (None, [])) if msg_id is not None else (None, [])
        if world is not None:
            left = self._in_flight.pop(world, 1) - 1
            if left > 0:
                self._in_flight[world] = left
            if world in self._queued and self._wake is not None:
                self._wake.set()
        return futs

    def _fail(self, futs: list[Future], why: str) -> None:
        for fut in futs:
            if not fut.done():
                fut.set_exception(Unreachable(None, f"{self.url}: {why}"))

    async def _flush(self) -> None:
        """Send queued (merged) commands as budget returns and their worlds' last are answered."""
        assert self._wake is not None
        while True:
            await self._wake.wait()
            self._wake.clear()  # before looking: an ack meanwhile sets it again
            while True:
                world = next(
                    (w for w in self._queued if self._in_flight.get(w, 0) < IN_FLIGHT), None
                )
                if world is None:
                    break
                if not self._take():
                    await asyncio.sleep(max(0.001, (1.0 - self._tokens) / self.rate))
                    continue
                values, futs = self._queued.pop(world)
                if self._ws is None:
                    self._fail(futs, "not connected to armfleet")
                else:
                    self._send(world, values, futs)

    async def run(self, stopping: Callable[[], bool]) -> None:
        self._wake = asyncio.Event()
        flusher = asyncio.ensure_future(self._flush())
        url = stream.ws_url(self.url, self.worlds, LANE_STATE_HZ, binary=True)
        backoff = stream.Backoff(maximum=1.0)
        try:
            while not stopping():
                try:
                    async with connect(
                        url,
                        max_size=stream.MAX_SIZE,
                        proxy=None,
                        additional_headers=auth.headers(),
                    ) as ws:
                        self._ws = ws
                        backoff.reset()
                        async for data in ws:
                            self._frame(data)
                except stream.LOST as exc:
                    log.debug("command lane: %s", stream.reason_for(exc))
                self._ws = None
                for _, futs in self._pending.values():
                    self._fail(futs, "connection lost")
                self._pending.clear()
                self._in_flight.clear()
                self._wake.set()  # what waited behind them: failed by the flusher
                await asyncio.sleep(backoff.next())
        finally:
            flusher.cancel()

    def _frame(self, data: Any) -> None:
        msg = stream.parse(data)
        if isinstance(msg, BatchStates):
            try:
                self.on_states(msg)
            except Exception:
                log.exception("publishing a state frame failed")
        elif isinstance(msg, (CommandAck, WsError)):
            for fut in self._answered(msg.id):
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
