"""CameraClock: one picture clock per camera and rate, shared by every stream reading it.

At each instant of the rate's grid (multiples of the period on the monotonic clock) the clock
asks the camera feed for ONE picture: the worlds of every reader ready for one, drawn in one
render at one tick. Each reader then gets its own worlds of it. Readers that are still busy
(their last picture is being drawn or waits behind the one being sent) skip that instant, so a
slow reader never makes the others wait and nothing piles up for it: newest only.

While the loop runs late in realtime (`SimLoop.late`), the clock skips its instants (counted as
given way), asking for at most one picture every GIVE_WAY_S: pictures wait for the ticks, never
the other way round.

Why one clock and not each socket asking at the grid's instants: sockets that each ask "now"
drift apart as soon as one picture comes late (eight readers ended up on two or three phases
of the grid and cost two or three renders a picture); a shared clock cannot split.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
import weakref

import numpy as np

from service.core.cameras.feed import CameraFeed, Shot
from service.core.errors import ArmfleetError, Unavailable

AHEAD = 3  # pictures a push reader may have drawing or waiting beyond the one it sends
# While the ticks run late, a clock still asks for one picture this often: one hand-over a
# second costs the loop next to nothing, and a stream on a machine that cannot keep real time
# for long (a loaded CPU) slows down instead of stopping.
GIVE_WAY_S = 1.0


class Reader:
    """One stream's place on a clock: the worlds it reads, and pictures drawing or drawn for
    it beyond the one it is sending: at most AHEAD (push; drawing a picture of 16,384 worlds
    takes longer than a period at 30 Hz, so with one ahead every other instant was missed) or
    what it asked (pull), and none while a drawn one waits for a sender that has been busy
    for a period or more (a slow reader holds back its own drawing; one whose send is young
    takes the waiting picture soon, long before another is drawn). A picture drawn while an
    older one still waits replaces it: newest only, so a slow reader gets fresh pictures, not
    a backlog; a push reader never gets the same tick twice."""

    def __init__(self, worlds: np.ndarray, pull: bool) -> None:
        self.worlds = np.asarray(worlds, dtype=np.int64)
        self.pull = pull
        self.asked = 0  # pull: pictures asked and not yet taken into a render
        self._drawing = 0  # pictures of ours being drawn
        self._newest = -1  # the tick of the newest picture handed to the sender or waiting
        self._next: Shot | BaseException | None = None  # drawn, not yet taken by the sender
        self._sending_since: float | None = None  # when the sender took the one it sends
        self._wake = asyncio.Event()

    def ready(self, now: float, period: float) -> bool:
        if self._next is not None:  # the sender has not taken the last one: it is busy
            since = self._sending_since
            if self.pull or since is None or now - since >= period:
                return False  # and slow (or pulling): nothing more is drawn for it
        if self.pull:
            return self.asked > 0 and self._drawing == 0
        return self._drawing < AHEAD

    def ask(self) -> None:
        """Pull: one more picture wanted."""
        self.asked += 1

    async def take(self) -> Shot:
        """The next picture for this reader (its own worlds); raises what drawing raised.
        From then until it asks for the next, the reader counts as sending it."""
        self._sending_since = None
        while self._next is None:
            self._wake.clear()
            await self._wake.wait()
        got, self._next = self._next, None
        self._sending_since = time.monotonic()
        if isinstance(got, BaseException):
            raise got
        return got

    def _drawn(self, got: Shot | BaseException) -> None:
        self._drawing -= 1
        if not self.pull and isinstance(got, Shot) and got.tick <= self._newest:
            return  # two asks met at one tick boundary: that tick is on its way already
        # (a pull reader gets what it asked for, even the same tick: paused, nothing moves)
        if isinstance(got, Shot):
            self._newest = got.tick
        self._next = got  # the feed draws in the order asked: a later one is newer
        self._wake.set()


class CameraClock:
    """The clock of one camera at one rate: see the module docstring."""

    def __init__(self, feed: CameraFeed, camera: str, rate: float) -> None:
        self.feed, self.camera, self.period = feed, camera, 1.0 / rate
        self.readers: set[Reader] = set()
        self._task: asyncio.Task[None] | None = None
        self._wake = asyncio.Event()  # a pull reader asked: no need to wait for the next instant
        self._asked_at = time.monotonic()  # when this clock last asked for a picture

    def join(self, reader: Reader) -> None:
        self.readers.add(reader)
        if self._task is None or self._task.done():
            self._task = asyncio.create_task(self._run())

    def leave(self, reader: Reader) -> None:
        self.readers.discard(reader)

    def poke(self) -> None:
        self._wake.set()

    async def _run(self) -> None:
        pictures: set[asyncio.Task[None]] = set()
        try:
            while self.readers:
                now = time.monotonic()
                at = math.ceil(now / self.period) * self.period
                self._wake.clear()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._wake.wait(), max(0.0, at - now))
                    # woken by a pull request: still on the grid (the rate is a ceiling)
                    await asyncio.sleep(max(0.0, at - time.monotonic()))
                now = time.monotonic()
                ready = [r for r in self.readers if r.ready(now, self.period)]
                if not ready:
                    continue
                if self.feed.ticks_late() and now - self._asked_at < GIVE_WAY_S:
                    self.feed.gave_way += 1  # ticks first: this instant's picture gives way
                    continue
                self._asked_at = now
                for r in ready:
                    r._drawing += 1
                    r.asked = max(0, r.asked - 1)
                task = asyncio.create_task(self._picture(ready))
                pictures.add(task)
                task.add_done_callback(pictures.discard)
        finally:
            for task in pictures:
                task.cancel()

    async def _picture(self, ready: list[Reader]) -> None:
        """One render of the ready readers' worlds; each reader is handed its own."""
        ready.sort(key=lambda r: int(r.worlds[0]) if len(r.worlds) else -1)
        ids, rows = _union(ready)
        try:
            shot = await self.feed.shoot_async(ids, self.camera)
        except ArmfleetError as exc:
            for r in ready:
                r._drawn(exc)
            return
        except asyncio.CancelledError:
            for r in ready:
                r._drawn(Unavailable("the stream stopped"))
            raise
        for r, at in zip(ready, rows, strict=True):
            r._drawn(shot if len(ready) == 1 else shot.only(r.worlds, at))


def _union(ready: list[Reader]) -> tuple[np.ndarray, list[slice | None]]:
    """The worlds of every reader, sorted and distinct, and where each reader's worlds lie
    among them: a slice when the readers' worlds follow each other in order (readers of
    disjoint ranges, the common case: no search), else None (found by `Shot.only`)."""
    parts = [r.worlds for r in ready]
    if len(parts) == 1:
        return parts[0], [slice(0, len(parts[0]))]
    ids = np.concatenate(parts)
    if len(ids) < 2 or bool(np.all(ids[1:] > ids[:-1])):
        ends = np.cumsum([len(p) for p in parts])
        return ids, [slice(int(e - len(p)), int(e)) for p, e in zip(parts, ends, strict=True)]
    return np.unique(ids), [None] * len(parts)


_CLOCKS: weakref.WeakKeyDictionary[CameraFeed, dict[tuple[str, float], CameraClock]]
_CLOCKS = weakref.WeakKeyDictionary()


def clock_for(feed: CameraFeed, camera: str, rate: float) -> CameraClock:
    """The clock of `camera` at `rate` of this feed (made when it has no readers)."""
    clocks = _CLOCKS.setdefault(feed, {})
    key = (camera, float(rate))
    if key not in clocks or not clocks[key].readers:
        clocks[key] = CameraClock(feed, camera, rate)
    return clocks[key]
