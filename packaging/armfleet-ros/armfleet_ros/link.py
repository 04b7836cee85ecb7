"""The node's line to armfleet: one asyncio thread holding its WebSockets, beside rclpy's threads.

Two sockets, both armfleet's public API read with armfleet's own client library (`clients`):

- the batch socket `WS /v1/ws?worlds=...&format=binary` for every served world: float32 state
  frames in (parsed by `clients.stream.parse`). One socket for 256 worlds costs one frame per
  tick instead of 256 JSON frames. Commands go out on command lanes (lanes.py: threads and
  sockets of their own, sending from the thread that took the ROS message).
- the pose socket `WS /v1/ws/view` (every body's world pose), opened only for the worlds whose
  `/tf` somebody listens to, and reopened when that set changes.

Both reconnect with the client's `Backoff` when armfleet restarts. Callbacks (`on_states`) run
on this thread; ROS publishers are thread-safe, so the node publishes from here at once, which
keeps a command's round trip to one state frame.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future
from typing import Any

import numpy as np
from websockets.asyncio.client import connect

from armfleet_ros import auth
from armfleet_ros.lanes import lanes_for
from clients import stream
from clients.models import BatchStates
from clients.wire import POSE_MAGIC

log = logging.getLogger("armfleet_ros")


class Poses:
    """One pose frame: world ids and every body's world pose, (n, nbody, 7) x y z w x y z."""

    def __init__(self, data: bytes) -> None:
        import orjson

        hlen = int.from_bytes(data[4:8], "little")
        header = orjson.loads(data[8 : 8 + hlen])
        n, nbody = int(header["n"]), int(header["nbody"])
        at = 8 + hlen
        self.tick = int(header["tick"])
        self.worlds = np.frombuffer(data, "<i4", n, at).astype(np.int64)
        at += 8 * n  # world ids, then faults
        self.poses = np.frombuffer(data, "<f4", n * nbody * 7, at).reshape(n, nbody, 7)
        self.row = {int(w): i for i, w in enumerate(self.worlds)}


class FleetLink:
    """State frames in, commands out, over WebSockets on a thread of its own."""

    def __init__(
        self,
        url: str,
        worlds: Sequence[int],
        rate: float,
        on_states: Callable[[BatchStates], None],
        command_rate: float = 200.0,
    ) -> None:
        self.url = url.rstrip("/")
        self.worlds = list(worlds)
        self.rate = rate
        self.on_states = on_states
        self.latest: BatchStates | None = None
        self.poses: Poses | None = None
        self.connected = False
        self.generation = 0  # connections so far: ticks may start over on a new one
        self._pose_worlds: tuple[int, ...] = ()
        self._pose_changed: asyncio.Event | None = None
        # a margin below armfleet's per-connection budget (clocks and bursts differ a little)
        self.lanes, self._lane_of = lanes_for(self.url, self.worlds, 0.9 * command_rate, on_states)
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._run, name="armfleet-link", daemon=True)
        self._stopping = False

    # -- life ------------------------------------------------------------------------------

    def start(self) -> None:
        self._thread.start()
        for lane in self.lanes:
            lane.start()

    def stop(self) -> None:
        self._stopping = True
        for lane in self.lanes:
            lane.stop()
        deadline = time.monotonic() + 5  # all told first: one that is connecting takes longest
        for lane in self.lanes:
            lane.join(max(0.0, deadline - time.monotonic()))
        for task in asyncio.all_tasks(self._loop) if self._loop.is_running() else ():
            self._loop.call_soon_threadsafe(task.cancel)
        self._thread.join(timeout=5)

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._pose_changed = asyncio.Event()
        try:
            self._loop.run_until_complete(asyncio.gather(self._states(), self._pose_stream()))
        except asyncio.CancelledError:
            pass
        except Exception:
            log.exception("armfleet link stopped")
        finally:
            self._drain()

    def _drain(self) -> None:
        """Let every task left (a socket still unwinding) finish being cancelled
        while the loop can still run it: one dropped pending would run its `finally` when it
        is collected, on a closed loop ("Event loop is closed" in the log at every stop)."""
        left = asyncio.all_tasks(self._loop)
        for task in left:
            task.cancel()
        if left:
            gathered = asyncio.gather(*left, return_exceptions=True)
            self._loop.run_until_complete(gathered)

    # -- commands (any thread) -------------------------------------------------------------

    def set_targets(self, world: int, targets: Mapping[str, float]) -> Future:
        """Send a target command on the world's lane, from this thread (lanes.py); the future
        gets its CommandAck, or CommandRejected with armfleet's reason, or Unreachable while
        armfleet is away."""
        fut: Future = Future()
        self._lane_of[world].submit(world, dict(targets), fut)
        return fut

    def watch_poses(self, worlds: Sequence[int]) -> None:
        """Ask for the body poses of `worlds` (empty: close the pose socket)."""
        wanted = tuple(sorted(set(int(w) for w in worlds)))
        if wanted != self._pose_worlds:
            self._pose_worlds = wanted
            if self._pose_changed is not None:
                self._loop.call_soon_threadsafe(self._pose_changed.set)

    # -- the sockets ------------------------------------------------------------------------

    async def _states(self) -> None:
        url = stream.ws_url(self.url, self.worlds, self.rate, binary=True)
        backoff = stream.Backoff(maximum=1.0)
        while not self._stopping:
            try:
                async with connect(
                    url, max_size=stream.MAX_SIZE, proxy=None, additional_headers=auth.headers()
                ) as ws:
                    async for data in ws:
                        self._frame(data, backoff)
                    reason = stream.close_reason(ws.close_code, ws.close_reason)
            except stream.LOST as exc:
                reason = stream.reason_for(exc)
            self._drop(reason)
            await asyncio.sleep(backoff.next())

    def _frame(self, data: Any, backoff: stream.Backoff) -> None:
        msg = stream.parse(data)
        if isinstance(msg, BatchStates):
            if not self.connected:
                self.connected = True
                self.generation += 1
                backoff.reset()
                log.info("connected to armfleet at %s (%d worlds)", self.url, len(self.worlds))
            self.latest = msg
            try:
                self.on_states(msg)
            except Exception:
                log.exception("publishing a state frame failed")

    def _drop(self, reason: str) -> None:
        if self.connected:
            log.warning("lost armfleet at %s: %s; reconnecting", self.url, reason)
        self.connected = False

    async def _pose_stream(self) -> None:
        assert self._pose_changed is not None
        while not self._stopping:
            self._pose_changed.clear()
            worlds = self._pose_worlds
            if not worlds:
                self.poses = None
                await self._pose_changed.wait()
                continue
            spec = ",".join(str(w) for w in worlds)
            url = stream.ws_url(self.url, None).replace("/v1/ws", "/v1/ws/view", 1)
            url += ("&" if "?" in url else "?") + f"worlds={spec}&rate={self.rate:g}"
            try:
                async with connect(
                    url, max_size=stream.MAX_SIZE, proxy=None, additional_headers=auth.headers()
                ) as ws:
                    reader = asyncio.ensure_future(self._read_poses(ws))
                    changed = asyncio.ensure_future(self._pose_changed.wait())
                    await asyncio.wait({reader, changed}, return_when=asyncio.FIRST_COMPLETED)
                    for task in (reader, changed):
                        task.cancel()
                    if changed.done() and not changed.cancelled():
                        continue
            except stream.LOST as exc:
                log.debug("pose socket: %s", stream.reason_for(exc))
            await asyncio.sleep(0.5)

    async def _read_poses(self, ws: Any) -> None:
        async for data in ws:
            if isinstance(data, bytes) and data[:4] == POSE_MAGIC:
                self.poses = Poses(data)
