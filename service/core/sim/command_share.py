"""Ticks first: how much of the time between two ticks the commands may take.

Why: commands run on the server's event loop, in Python, under the same GIL as the sim thread's
Python, and on the same cores as the engine's shards. Under a load of commands the event loop
never idles: the sim thread then waits for the GIL after every engine call and the shards share
their cores with command work, so the ticks fall behind (issue 39: 1,000 commands/s on 64 worlds
on 2 cores ran the worlds at 0.25-0.32 of real time). Nothing in the OS knows that the ticks
come first; this does.

How: in real time, each tick tells the share how late it started (`ticked`). Late by more than
half a tick: the command budget of the next tick is halved; on time: it grows by a fiftieth of
a tick, up to a whole tick (additive increase, multiplicative decrease). The surfaces measure
the work each command cost (`spent`) and, once this tick's budget is used, wait for the next
tick (`wait_s`) before taking another command: the command waits, in order, on its own
connection (the socket is not read meanwhile, so the client's sends wait in TCP), and the GIL and
the cores go to the tick. A floor keeps commands moving while the ticks are late anyway (a slow
engine, a box shared with others). In fast or paused mode, or with `enabled` off, nothing waits.

The sim thread writes (`ticked`, `active`), the event loop reads and counts its own spending; a
stale read costs one command's worth of work, never a wrong result, so no lock is taken.
"""

from __future__ import annotations

import time

# The budget never shrinks below this share of a tick: commands always move.
FLOOR_SHARE = 0.03
GROW_SHARE = 0.02  # an on-time tick adds this share of a tick to the budget
SHRINK = 0.5  # a late tick multiplies the budget by this
LATE_SHARE = 0.5  # a tick that starts later than this share of a tick is late
MAX_WAIT_S = 1.0  # no command waits longer than this for its turn (a stalled loop)


class CommandShare:
    """The command budget per tick beside the ticks (see the module docstring)."""

    def __init__(self, tick_dt: float, enabled: bool = True) -> None:
        self.tick_dt = tick_dt
        self.enabled = enabled
        self.active = False  # real time and running: the sim thread says (`set_active`)
        self.budget_s = tick_dt  # command seconds per tick (sim thread)
        self.ticks = 0  # ticks told so far (sim thread)
        self.tick_end = time.monotonic()  # when the last tick was told (sim thread)
        self.late_ticks = 0  # ticks that started late (metrics)
        # event loop side
        self._spent_s = 0.0
        self._spent_tick = 0
        self.waits = 0  # commands that waited for a later tick (metrics)
        self.waited_s = 0.0

    # -- the sim thread ---------------------------------------------------------------------

    def set_active(self, active: bool) -> None:
        """Real time (True) or not: only real-time ticks have a deadline to keep."""
        self.active = active

    def ticked(self, late_s: float) -> None:
        """A real-time tick ended that started `late_s` after its deadline."""
        dt = self.tick_dt
        if late_s > LATE_SHARE * dt:
            self.late_ticks += 1
            self.budget_s = max(FLOOR_SHARE * dt, self.budget_s * SHRINK)
        else:
            self.budget_s = min(dt, self.budget_s + GROW_SHARE * dt)
        self.tick_end = time.monotonic()
        self.ticks += 1

    # -- the event loop ---------------------------------------------------------------------

    def wait_s(self) -> float:
        """0: a command may run now; else how long to sleep before asking again (the next
        tick should have ended by then)."""
        if not (self.enabled and self.active):
            return 0.0
        if self._spent_tick != self.ticks:  # a new tick: a new budget
            self._spent_tick, self._spent_s = self.ticks, 0.0
            return 0.0
        if self._spent_s < self.budget_s:
            return 0.0
        until_next = self.tick_end + self.tick_dt - time.monotonic()
        return min(max(until_next, 0.1 * self.tick_dt), self.tick_dt)

    def spent(self, seconds: float) -> None:
        """A command took `seconds` of the event loop (its parse, check, staging and ack)."""
        self._spent_s += seconds

    def waited(self, seconds: float) -> None:
        """A command waited `seconds` for its turn (counted for /metrics)."""
        self.waits += 1
        self.waited_s += seconds


async def turn(share: CommandShare) -> None:
    """Wait (on the event loop) until `share` lets a command run, at most `MAX_WAIT_S`."""
    import asyncio

    wait = share.wait_s()
    if wait <= 0:
        return
    t0 = time.monotonic()
    while wait > 0 and time.monotonic() - t0 < MAX_WAIT_S:
        await asyncio.sleep(wait)
        wait = share.wait_s()
    share.waited(time.monotonic() - t0)
