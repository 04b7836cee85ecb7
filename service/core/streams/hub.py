"""StreamHub: fans state out to WebSocket subscribers with latest-state delivery.

Each subscription holds at most one undelivered frame (a newer one replaces it) plus its queue
of command acks, which are never dropped. A slow reader therefore costs one frame of memory and
delays nobody else; a fast one gets every frame it asked for, at most one per tick.

Batch subscriptions (`packed`: many worlds, binary or JSON) never need a snapshot: on the sim
thread, after each tick, the hub asks the engine for the rows of the worlds they watch (once
per selection, however many sockets share it) and its FrameSender thread serialises them
(service.core.streams.frames); the event loop only sends. The other subscriptions (one world,
the page's pose frames) are rendered from snapshots, as is every subscription's first frame.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any, Protocol

import numpy as np

from service.core.sim import safety
from service.core.sim.batch import Batch
from service.core.sim.loop_types import SnapshotSink
from service.core.sim.types import Snapshot
from service.core.streams import entity_frames, frames
from service.core.streams.formats import WITH_ENTITIES, FrameFormat

log = logging.getLogger("armfleet.hub")


class SafetyModes(Protocol):
    """Where packed frames get the worlds' safety modes (the loop's safety table)."""

    def modes(self) -> np.ndarray: ...


class TrajectoryBriefs(Protocol):
    """Where packed JSON frames get the worlds' trajectory briefs (the trajectory manager)."""

    def briefs(self, worlds: np.ndarray) -> dict[str, dict[str, Any]]: ...


def _without_entities(snap: Snapshot) -> bool:
    """A snapshot taken before a subscriber asked for entities has none: the next one will."""
    return snap.entities is None


class Subscription:
    """One WebSocket's interest: which worlds, how often, and its outbox."""

    def __init__(
        self,
        worlds: np.ndarray,
        rate: float | None,
        fmt: FrameFormat,
        render: Callable[[Snapshot], bytes],
        *,
        skip: Callable[[Snapshot], bool] | None = None,
        close: Callable[[int, str], Awaitable[None]] | None = None,
        ready: asyncio.Event | None = None,
    ):
        """`fmt` says what the frames are (formats.py); `render` makes one from a snapshot
        (the first frame, and every frame of a format that is not packed). `skip`: the writer
        drops a frame it says so of (the page's socket: nothing moved); frames with entities
        skip snapshots taken before anyone asked for them. `close`: closes the owning socket
        (code, reason), e.g. 1001 at shutdown. `ready`: an event shared with other
        subscriptions of one socket (rosbridge: one writer for every topic)."""
        # A read-only copy of its own: an engine may know the selection by this very array
        # (warp_frames.DevicePacker), so its ids never change.
        self.worlds = np.array(worlds)
        self.worlds.flags.writeable = False
        self.format = fmt
        self.entities = fmt.entities
        self.binary = fmt.binary  # frames go out as binary WebSocket messages
        self.packed = fmt.packed
        self.names = list(fmt.names)
        self.status_frames = fmt.status_frames
        # Sockets with the same kind of frame over the same worlds share one serialisation.
        self.key = (fmt.key, self.worlds.tobytes())
        self.period = 1.0 / rate if rate else 0.0  # 0: every tick
        self.render = render
        if skip is None and fmt.entities:
            skip = _without_entities
        self.skip = skip
        self.close = close
        self.ready = ready if ready is not None else asyncio.Event()
        self.frame: bytes | None = None  # the newest packed frame not yet sent
        self.claimed_tick = -1  # the tick of the last packed frame asked for (sim thread)
        self._owed_lock = threading.Lock()  # owed_tick is read on the sim thread too
        self.next_due = 0.0
        self.latest: Snapshot | None = None
        self.owed_tick: int | None = None  # the earliest tick an acked command takes effect
        self.acks: deque[bytes] = deque()

    def due(self, now: float) -> bool:
        # A little slack so that a 30 Hz stream on a 60 Hz loop really gets every other tick.
        return now >= self.next_due - 0.1 * self.period

    def owe(self, tick: int) -> None:
        """A command from this socket takes effect at `tick`: send the first frame that carries
        it whatever the cadence (called on the event loop when the command is acked)."""
        with self._owed_lock:
            self.owed_tick = tick if self.owed_tick is None else min(self.owed_tick, tick)

    def _pay(self, tick: int) -> bool:
        """Whether a frame of `tick` is owed; if so the debt is settled."""
        with self._owed_lock:
            if self.owed_tick is not None and tick >= self.owed_tick:
                self.owed_tick = None
                return True
            return False

    def _keep_cadence(self, now: float) -> None:
        if self.period and self.due(now):
            # Keep the cadence; after a stall start afresh instead of sending a burst. A frame
            # sent early because a command was owed does not move the cadence.
            self.next_due += self.period
            if self.next_due < now:
                self.next_due = now + self.period

    def claim(self, tick: int, now: float) -> bool:
        """Packed subscriptions, on the sim thread: is a frame of `tick` wanted? (If so, the
        cadence moves on as `offer` moves it.)"""
        owed = self._pay(tick)
        if not (owed or self.due(now)):
            return False
        self._keep_cadence(now)
        self.claimed_tick = tick
        return True

    def catch_up(self, tick: int) -> bool:
        """Packed subscriptions, where time stopped at `tick`: is their last frame older? (The
        frame sent for it leaves the cadence as it is, like an owed one.)"""
        if self.claimed_tick >= tick:
            return False
        self._pay(tick)
        self.claimed_tick = tick
        return True

    def wants(self, snap: Snapshot, now: float) -> bool:
        return self.due(now) or (self.owed_tick is not None and snap.tick >= self.owed_tick)

    def offer(self, snap: Snapshot, now: float) -> None:
        self.latest = snap  # replaces one the reader has not taken yet
        self._pay(snap.tick)
        self._keep_cadence(now)
        self.ready.set()

    def offer_frame(self, frame: bytes) -> bool:
        """A packed frame (event loop); True if it replaced one the reader had not taken."""
        replaced = self.frame is not None or self.latest is not None
        self.frame, self.latest = frame, None
        self.ready.set()
        return replaced

    def push_ack(self, message: bytes) -> None:
        self.acks.append(message)
        self.ready.set()


class StreamHub(SnapshotSink):
    """The loop's snapshot sink: decides demand on the sim thread, delivers on the event loop."""

    def __init__(
        self,
        aio_loop: asyncio.AbstractEventLoop,
        briefs: TrajectoryBriefs | None = None,
        safety: SafetyModes | None = None,
    ):
        self._aio = aio_loop
        self._briefs = briefs  # what packed JSON frames say of the worlds' trajectories
        self._safety = safety  # and of the worlds' safety modes (None: all NORMAL)
        self._subs: tuple[Subscription, ...] = ()  # replaced, never mutated: read from two threads
        self._lock = threading.Lock()
        self._incoming: Snapshot | None = None
        self._scheduled = False
        self._frame_cache: dict[tuple[int, tuple[str, bytes]], bytes] = {}
        self.frames_skipped = 0  # frames replaced before a slow reader took them (metrics)
        self.streams_direct = 0  # sockets written by a thread of their own (service/api/ws.py)
        self._sender: frames.FrameSender | None = None  # started with the first packed socket
        self._resync = False  # after a restore, packed sockets get the restored snapshot too

    def add(self, sub: Subscription) -> None:
        if sub.packed and self._sender is None:
            self._sender = frames.FrameSender(self._frames_ready)
        self._subs = (*self._subs, sub)

    def stop(self) -> None:
        """Stop the frame thread (the service is stopping)."""
        if self._sender is not None:
            self._sender.stop()

    def remove(self, sub: Subscription) -> None:
        self._subs = tuple(s for s in self._subs if s is not sub)

    @property
    def subscribers(self) -> int:
        return len(self._subs)

    def extend_snapshot(self, snap: Snapshot, batch: Batch) -> Snapshot:
        """The loop's snapshot about to be published, with every world's entities while some
        subscriber asked for them (sim thread, at the snapshot's tick); as it is otherwise."""
        if any(s.entities for s in self._subs):
            return entity_frames.attach(snap, batch)
        return snap

    # -- sim thread -------------------------------------------------------------------------

    def wants_snapshot(self, now: float) -> bool:
        return any(s.due(now) or s.owed_tick is not None for s in self._subs if not s.packed)

    def on_tick(self, batch: Batch, now: float) -> None:
        """Pack the frames packed subscriptions want of this tick, one per world selection."""
        self._pack(batch, [s for s in self._subs if s.packed and s.claim(batch.tick, now)])

    def at_rest(self, batch: Batch, now: float) -> None:
        """Time stopped: packed subscriptions whose last frame is older get this tick's now,
        whatever their cadence (a burst of steps ends between two frames of a slow one)."""
        self._pack(batch, [s for s in self._subs if s.packed and s.catch_up(batch.tick)])

    def _pack(self, batch: Batch, subs: list[Subscription]) -> None:
        groups: dict[bytes, list[Subscription]] = {}
        for sub in subs:
            groups.setdefault(sub.key[1], []).append(sub)
        for selection, group in groups.items():
            formats = sorted({s.packed for s in group if s.packed})
            json = any(f.startswith("json") for f in formats)
            data = frames.pack(batch, group[0].worlds, json)
            if data is None or self._sender is None:
                self.frames_skipped += len(group)
                continue
            if self._safety is not None:  # the binary frames' last block, as of this tick
                data.safety = self._safety.modes()[group[0].worlds]
            if json:
                data.extra = frames.json_extra(len(group[0].worlds))
                if data.safety is not None:  # as `wire.batch_frame` names them
                    data.extra["safety_mode"] = safety.names(data.safety)
                if self._briefs is not None and any(s.format.trajectories for s in group):
                    data.extra["trajectories"] = self._briefs.briefs(group[0].worlds)
            asked = [f for f in formats if f in WITH_ENTITIES]
            if asked and not self._read_entities(batch, data):
                formats = [f for f in formats if f not in asked]
                self.frames_skipped += sum(s.packed in asked for s in group)
            self._sender.submit(frames.Job(data, formats, group, group[0].names, selection))

    @staticmethod
    def _read_entities(batch: Batch, data: frames.FrameData) -> bool:
        """The frame's worlds' entities, of the tick of its rows (sim thread); False when the
        engine cannot give them now (a Ray shard being rebuilt): that frame is skipped."""
        try:
            data.entities = entity_frames.read(batch, data.ids)
        except Exception:
            log.exception("the entities of tick %d could not be read", data.tick)
            return False
        return True

    def restored(self) -> None:
        """The batch was restored: the next snapshot goes to packed subscriptions as well."""
        self._resync = True
        for sub in self._subs:  # ticks may start lower: any tick now is news to them
            sub.claimed_tick = -1

    def publish(self, snapshot: Snapshot) -> None:
        if not self._subs:
            return
        with self._lock:
            self._incoming = snapshot  # a newer snapshot supersedes one not yet delivered
            if self._scheduled:
                return
            self._scheduled = True
        self._aio.call_soon_threadsafe(self._deliver)

    # -- event loop -------------------------------------------------------------------------

    def _deliver(self) -> None:  # now from time.monotonic, the same clock as the sim thread
        with self._lock:
            snap, self._incoming = self._incoming, None
            self._scheduled = False
        if snap is None:
            return
        now = time.monotonic()
        resync, self._resync = self._resync, False
        for sub in self._subs:
            if sub.packed and not resync:
                continue
            if sub.wants(snap, now) or (sub.packed and resync):
                if sub.latest is not None:
                    self.frames_skipped += 1
                sub.offer(snap, now)

    def _frames_ready(self, job: frames.Job, out: dict[str, bytes]) -> None:
        """FrameSender thread: hand the bytes to the event loop."""
        self._aio.call_soon_threadsafe(self._deliver_frames, job, out)

    def _deliver_frames(self, job: frames.Job, out: dict[str, bytes]) -> None:
        live = set(map(id, self._subs))
        for sub in job.targets:
            if id(sub) in live and sub.packed in out and sub.offer_frame(out[sub.packed]):
                self.frames_skipped += 1

    def broadcast(self, message: bytes) -> None:
        """Queue a message (a status frame) for every subscriber, in order with its acks."""
        for sub in self._subs:
            if sub.status_frames:
                sub.push_ack(message)

    async def close_all(self, code: int, reason: str) -> None:
        """Close every subscriber's socket with `code` (1001 when the service stops)."""
        closing = [sub.close(code, reason) for sub in self._subs if sub.close is not None]
        await asyncio.gather(*closing, return_exceptions=True)

    def frame(self, sub: Subscription, snap: Snapshot) -> bytes:
        """Serialise once per (tick, world selection) however many sockets share it."""
        key = (snap.tick, sub.key)
        frame = self._frame_cache.get(key)
        if frame is None:
            if len(self._frame_cache) > 256:
                self._frame_cache.clear()
            frame = self._frame_cache[key] = sub.render(snap)
        return frame
