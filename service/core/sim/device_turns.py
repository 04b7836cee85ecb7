"""DeviceTurns: whose turn it is to launch work on a CUDA device, the loop's or the renderer's.

Warp's current stream is one per device, not one per thread, and MuJoCo Warp's functions
launch on it. The camera renderer draws on a stream of its own, so that the device runs a
picture beside the engine's ticks instead of in line with them (on one stream a tick waited
behind the picture queued before it, and the next picture's hand-over waited for that tick:
ticks and pictures took turns on the device). It does so by making its stream the device's
current one for the few milliseconds its launches take; meanwhile the loop's thread must not
launch, or its work would land on the renderer's stream. So launching is taken in turns: the
loop's thread holds a turn for each tick and each batch of requests it serves, the renderer
for each picture's launches. A waiting renderer goes before the loop's next turn: with a plain
lock the loop, which takes its turn again at once in fast mode, would keep it. While the loop's
thread waits for the device inside its turn (a tick's results coming to the host), it lends
the turn (`lent`): a picture's launches then wait for neither the tick nor the copy.

Engines that share a device with the renderer (warp on CUDA) carry one as `device_turns`;
for the others the loop's turns cost an uncontended lock.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator


class DeviceTurns:
    """Turns to launch on one device: `loop_turn` (the loop's thread), `render_turn`."""

    def __init__(self) -> None:
        # The condition's own lock, taken directly where nobody need be woken: a Condition's
        # `with` and `notify_all` are Python calls, ~1.5 us of each of the loop's turns.
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._sleepers = 0  # threads waiting on `_cond` (woken at a release only if any)
        self._busy = False
        self._holder: int | None = None  # the thread whose turn it is
        self._renders_waiting = 0

    def loop_turn(self) -> _LoopTurn:
        """The loop's turn; a turn already held by this thread goes on (a request served in a
        turn may serve another). A plain object, not a generator: the loop takes two turns a
        tick, each ~3.5 us of the sim thread's time through contextlib and the Condition's
        own `with` (bench/results/issue39/gpu7)."""
        return _LoopTurn(self)

    @contextlib.contextmanager
    def render_turn(self) -> Iterator[None]:
        """The renderer's turn, for one picture's launches: it waits for the turn held now,
        and goes before the loop's next one."""
        self._acquire(threading.get_ident(), render=True)
        try:
            yield
        finally:
            self._release()

    def _acquire(self, me: int, render: bool) -> None:
        """Wait for the device to be free, then hold it. The loop also waits while a renderer
        waits (renderers go first); a waiting renderer is counted so that the loop sees it."""
        with self._lock:
            if render:
                self._renders_waiting += 1
            try:
                while self._busy or (not render and self._renders_waiting):
                    self._sleep()
            finally:
                if render:
                    self._renders_waiting -= 1
            self._busy, self._holder = True, me

    @contextlib.contextmanager
    def lent(self) -> Iterator[None]:
        """While the thread holding a turn waits for the device (launching nothing), a
        renderer may take its turn; the holder's turn goes on after. Elsewhere: nothing."""
        me = threading.get_ident()
        if self._holder != me:
            yield
            return
        self._release()
        try:
            yield
        finally:
            with self._lock:
                while self._busy:
                    self._sleep()
                self._busy, self._holder = True, me

    def _sleep(self) -> None:
        """Wait for a release (the lock held), counted so that a release knows to wake."""
        self._sleepers += 1
        try:
            self._cond.wait()
        finally:
            self._sleepers -= 1

    def _release(self) -> None:
        with self._lock:
            self._busy, self._holder = False, None
            if self._sleepers:
                self._cond.notify_all()


class _LoopTurn:
    """`DeviceTurns.loop_turn`'s context: takes the turn unless this thread holds it already,
    and gives back only what it took."""

    __slots__ = ("_took", "_turns")

    def __init__(self, turns: DeviceTurns) -> None:
        self._turns = turns
        self._took = False

    def __enter__(self) -> None:
        turns, me = self._turns, threading.get_ident()
        if turns._holder != me:
            turns._acquire(me, render=False)
            self._took = True

    def __exit__(self, *exc: object) -> None:
        if self._took:
            self._took = False
            self._turns._release()
