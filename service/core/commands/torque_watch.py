"""The torque watch: a world whose arm pushes at a joint's torque limit without moving is
protective-stopped, on every world (UR ports or not), whatever surface drove it there.

A UR stops (protective stop) when the force it needs departs from what its model expects: the
arm hit something, is driven into it, or carries more than it can. armfleet's arm is driven by
position servos whose torque is capped at the UR10e's joint torque limits (330, 330, 150, 54,
54, 54 N·m, the actuators' force range), so "departs from the model" shows as a servo held at
its cap: when any arm joint's torque is at `SATURATED` of its limit while that joint stands
still (|qd| < `STALL_SPEED`) for `HOLD_S` of simulated time, the world is stopped. The
`ProtectiveStop` command holds the arm where it is and stops its trajectory in the same step
as the mode changes (safety_stop.py), and every surface reports the mode until it is unlocked.

Why "stands still" besides the cap: armfleet takes raw position targets on every surface, and
a target stepped by 0.6 rad or more saturates a servo for longer than `HOLD_S` while the joint
accelerates freely (shoulder_pan_joint +1 rad: 0.1 s at its cap, +2 rad: 0.33 s; measured on
native MuJoCo). That is a hard acceleration, which a UR's model expects; a blocked joint at
its cap does not move. A joint that sags under a load it cannot carry moves until something
stops it, and is stopped then.

When: at every snapshot the loop publishes (`publish`), for all worlds at once in a few array
operations. Snapshots come at least 10 times a second and at every tick that a sink asks for;
this watch asks for every tick while any world is at its cap and still (`wants_snapshot`), so
the hold is counted tick by tick once it starts, at the cost of a snapshot per tick only then.
A world counts again from zero after a stop, a restore to an earlier tick, or a tick at which
it moved or eased off.
"""

from __future__ import annotations

import logging

import numpy as np

from service.core.commands.control import Control
from service.core.commands.safety_stop import ProtectiveStop
from service.core.errors import ArmfleetError
from service.core.sim.loop_types import SnapshotSink
from service.core.sim.safety import NORMAL
from service.core.sim.types import Snapshot

__all__ = ["HOLD_S", "SATURATED", "STALL_SPEED", "TorqueWatch", "watch_torque"]

log = logging.getLogger("armfleet.safety")
SOURCE = "safety"  # the source label of the stops it raises (metrics, recordings)
ARM = 6  # the arm's joints come first
SATURATED = 0.98  # of the joint's torque limit
STALL_SPEED = 0.05  # rad/s: a joint slower than this stands still
HOLD_S = 0.05  # s of simulated time at the cap, standing still, before the stop


class TorqueWatch(SnapshotSink):
    """Stops every world whose arm is held at a joint's torque limit (module docstring)."""

    def __init__(self, control: Control, limits: np.ndarray, tick_dt: float) -> None:
        self.control = control
        self.limits = np.asarray(limits, np.float64)[:ARM]
        # the threshold in the snapshots' float32: compared without converting 7 columns
        self._cap = (SATURATED * self.limits).astype(np.float32)
        self.hold = max(1, round(HOLD_S / tick_dt))  # ticks
        self._since = np.full(control.nworld, -1, dtype=np.int64)  # tick the hold began
        self._holding = False  # any world at its cap and still at the last snapshot
        self.checked = 0  # snapshots judged so far

    def wants_snapshot(self, now: float) -> bool:
        return self._holding

    def publish(self, snap: Snapshot) -> None:
        self.checked += 1
        effort = np.abs(snap.effort[:, :ARM])
        hot = effort >= self._cap
        if not hot.any():  # the common case: one comparison of the whole batch
            if self._holding:
                self._since.fill(-1)
                self._holding = False
            return
        hot &= np.abs(snap.velocity[:, :ARM]) < STALL_SPEED
        held = hot.any(axis=1)
        if snap.safety is not None:  # a stopped world is held already: nothing to count
            held &= snap.safety == NORMAL
        since = self._since
        since[~held | (since > snap.tick)] = -1  # eased off, moved, or restored to before
        since[held & (since < 0)] = snap.tick
        self._holding = bool(held.any())
        due = np.flatnonzero(held & (snap.tick - since >= self.hold))
        if due.size:
            self._stop(snap, due, hot)

    def _stop(self, snap: Snapshot, due: np.ndarray, hot: np.ndarray) -> None:
        safety = self.control.loop.safety
        for world in due.tolist():
            self._since[world] = -1  # after an unlock it counts from zero
            if safety.mode(world) != NORMAL:
                continue
            ratio = np.where(hot[world], np.abs(snap.effort[world, :ARM]) / self.limits, 0.0)
            j = int(np.argmax(ratio))
            name = self.control.spec.names[j]
            why = (
                f"{name} held at its torque limit ({abs(float(snap.effort[world, j])):.0f} of "
                f"{self.limits[j]:.0f} N·m, not moving) for {HOLD_S:g} s: the arm is blocked"
            )
            held = np.asarray(snap.position[world, :ARM], np.float64)
            try:
                self.control.run(ProtectiveStop.create(self.control, world, held, why), SOURCE)
            except ArmfleetError:  # never lose the watch over one world's stop
                log.exception("world %d: the protective stop failed", world)


def watch_torque(control: Control) -> TorqueWatch:
    """The watch of every world, added to the loop's sinks."""
    loop = control.loop
    limits = np.array([j.effort_limit for j in control.spec.joints])
    watch = TorqueWatch(control, limits, loop.batch.tick_dt)
    loop.listeners.add_sink(watch)
    log.info(
        "torque watch: an arm joint at %g%% of its torque limit, not moving, for %g s is a "
        "protective stop (limits %s N·m)",
        SATURATED * 100,
        HOLD_S,
        ", ".join(f"{v:g}" for v in watch.limits),
    )
    return watch
