"""Ticks first: how much of the time between two ticks the commands may take.

Why: commands run on the server's event loop, in Python, under the same GIL as the sim thread's
Python, and on the same cores as the engine's shards. Under a load of commands the event loop
never idles: the sim thread then waits for the GIL after every engine call and the shards share
their cores with command work, so the ticks fall behind (1,000 commands/s on 64 worlds on 2
cores ran the worlds at 0.25-0.32 of real time). Nothing in the OS knows that the ticks come
first; this does.

How: in real time, each tick tells the share whether it started late (`ticked`), by the loop's
one lateness rule (`pace.Cadence.late`: behind by more than `pace.LATE_S`, on the way to giving
time up; the cameras' stream pictures give way by the same rule). Late: the command budget of
the next tick is halved; on time: it grows by a fiftieth of a tick, up to a whole tick
(additive increase, multiplicative decrease). The surfaces measure
the work each command cost (`spent`, in the event loop thread's CPU seconds: `cpu_now`) and,
once this tick's budget is used, wait for the next
tick (`turn`) before taking another command: the command waits, in order, on its own
connection (the socket is not read meanwhile, so the client's sends wait in TCP), and the GIL and
the cores go to the tick. Waiters share one future per tick, resolved by the sim thread (or a
timer, should the tick not come), so a thousand waiting sockets cost one wake-up a tick. The
budget never falls below `FLOOR_SHARE` of the wall time between two ticks: when the ticks are
slow for reasons of their own (a slow engine, a box shared with others), commands still move.
A command that finds no turn within `max_wait_s` is refused ("busy: ...", naming the limit)
rather than run over the ticks' time. In fast or paused mode, or with `enabled` off, nothing
waits. Within the budget the operating system still shares the cores between the event loop and
the engine; so with ticks first, in a service started in real time, the event loop's thread
runs at a lower priority (`REQUESTS_NICE`, set by the runtime once the ticks' threads started).

What a command is charged is the CPU its thread used (`cpu_now`, the thread's CPU clock), not
the wall time it took: what the ticks lose to a command is the core and the GIL it held, and
its wall time also counts what others took from it, the ticks' own GIL turns (the sim thread's
Python, asked for every `pace.SWITCH_INTERVAL_S`) and every other process on a shared box
(the event loop runs `REQUESTS_NICE` below them). Charged by wall time, a box busy with others
made commands look 12 times their cost (the ROS node's 1,000/s flood at 256 worlds, load 20
on 2 cores: 1.66 ms of wall time per command for 0.135 ms of CPU), the budget ran out on
time nobody spent on commands, and 1,250 of 3,000 commands were refused as busy while the
event loop used 5% of a core for them.

The sim thread writes (`ticked`, `set_active`), the event loop reads and counts its own
spending; a stale read costs one command's worth of work or one tick's wait, never a wrong
result, so no lock is taken.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

# The budget never shrinks below this share of the wall time between two ticks: commands move.
FLOOR_SHARE = 0.1
GROW_SHARE = 0.02  # an on-time tick adds this share of a tick to the budget
SHRINK = 0.5  # a late tick multiplies the budget by this
MAX_WAIT_S = 1.0  # default: a command that finds no turn within this is refused
# The event loop's thread runs this many nice steps below the ticks' threads (core/process/
# priority.py): under contention the scheduler gives an engine thread about 3x its share (CFS
# weights 1024 vs 335), and the event loop still runs whenever a core is free.
REQUESTS_NICE = 5


class CommandShare:
    """The command budget per tick beside the ticks (see the module docstring)."""

    def __init__(self, tick_dt: float, enabled: bool = True, max_wait_s: float = MAX_WAIT_S):
        self.tick_dt = tick_dt
        self.enabled = enabled
        self.max_wait_s = max_wait_s
        self.active = False  # real time and running: the sim thread says (`set_active`)
        self.budget_s = tick_dt  # command seconds per tick (sim thread)
        self.ticks = 0  # ticks told so far (sim thread)
        self.tick_end = time.monotonic()  # when the last tick was told (sim thread)
        self.late_ticks = 0  # ticks that started late (metrics)
        self._wake: Callable[[], None] | None = None  # resolves the waiters' future
        # event loop side
        self._spent_s = 0.0
        self._spent_tick = 0
        self._next: asyncio.Future[None] | None = None
        self.waits = 0  # commands that waited for a later tick (metrics)
        self.busy = 0  # commands refused for finding no turn within max_wait_s (metrics)

    @property
    def busy_detail(self) -> str:
        """What a command refused for want of a turn is told: the limit, by name."""
        return (
            f"busy: no turn within {self.max_wait_s:g} s beside the ticks (--command-wait-s); "
            "commands come faster than the service takes them: slow down or retry"
        )

    # -- the sim thread ---------------------------------------------------------------------

    def set_active(self, active: bool) -> None:
        """Real time (True) or not: only real-time ticks have a deadline to keep."""
        self.active = active
        if not active:
            self._release()

    def ticked(self, late: bool) -> None:
        """A real-time tick ended; `late`: it started late (`pace.Cadence.late`)."""
        dt, now = self.tick_dt, time.monotonic()
        floor = FLOOR_SHARE * max(dt, now - self.tick_end)  # the wall time since the last one
        if late:
            self.late_ticks += 1
            self.budget_s = max(floor, self.budget_s * SHRINK)
        else:
            self.budget_s = max(floor, min(dt, self.budget_s + GROW_SHARE * dt))
        self.tick_end = now
        self.ticks += 1
        self._release()

    def _release(self) -> None:
        wake, self._wake = self._wake, None
        if wake is not None:
            wake()

    # -- the event loop ---------------------------------------------------------------------

    def may_run(self) -> bool:
        """A command may run now: not real time, or this tick's budget is not used up."""
        if not (self.enabled and self.active):
            return True
        if self._spent_tick != self.ticks:  # a new tick: a new budget
            self._spent_tick, self._spent_s = self.ticks, 0.0
        return self._spent_s < self.budget_s

    def next_tick(self) -> asyncio.Future[None]:
        """A future that the end of the next tick resolves (shared by every waiter), or a
        timer two ticks later should that tick not come."""
        fut = self._next
        if fut is None or fut.done():
            loop = asyncio.get_running_loop()
            fut = self._next = loop.create_future()
            self._wake = lambda: loop.call_soon_threadsafe(_resolve, fut)
            loop.call_later(2 * self.tick_dt, _resolve, fut)
        return fut

    def spent(self, seconds: float) -> None:
        """A command took `seconds` of the event loop's CPU (its parse, check, staging and ack;
        measured with `cpu_now`)."""
        self._spent_s += seconds


def cpu_now() -> float:
    """The calling thread's CPU seconds so far: a command is charged the difference over its
    work (see the module docstring: the CPU it took, not the wall time others took from it)."""
    return time.thread_time()


def _resolve(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


async def turn(share: CommandShare, wait: bool = True) -> bool:
    """Wait (on the event loop) until `share` lets a command run: True; False when no turn came
    within `share.max_wait_s` (refuse the command with `share.busy_detail`). `wait` False: no
    waiting, False at once unless the command may run now (a connection just refused as busy
    has its queued commands refused at once, so that its backlog, and the pings queued behind
    it, are not held `max_wait_s` each)."""
    if share.may_run():
        return True
    if not wait:
        share.busy += 1
        return False
    share.waits += 1
    deadline = time.monotonic() + share.max_wait_s
    while time.monotonic() < deadline:
        await share.next_tick()
        if share.may_run():
            return True
    share.busy += 1
    return False
