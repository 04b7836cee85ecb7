"""When a UR world's arm is protective-stopped for its torque: a joint pushing at its limit.
(A commanded target into a fixed obstacle stops any world: core/commands/clearance_watch.py.)

A UR stops (protective stop) when the force it needs departs from what its model expects: the
arm hit something, or is driven into it. armfleet's arm is driven by position servos whose
torque is capped at the UR10e's joint torque limits (330, 330, 150, 56, 56, 56 N·m, the
actuators' force range); a servo held at that cap means the arm cannot follow its target: it
is pressed against the table, a body, or itself, or carries more than it can. When any arm
joint's torque stays at `SATURATED` of its limit for `HOLD_S` of simulated time, the world is
protective-stopped (world_robot.py): the arm holds where it is, the program ends, and every
surface reports the safety mode until the Dashboard unlocks it. Brief peaks (a hard
acceleration) do not count. Runs on the sim thread with every snapshot; only worlds with UR
ports are watched, and each world's count is its own.
"""

from __future__ import annotations

import numpy as np

from service.core.sim.types import Snapshot

SATURATED = 0.98  # of the joint's torque limit
HOLD_S = 0.05  # s of simulated time at the limit before the stop
ARM = 6


class SafetyWatch:
    """Counts, per world, how long an arm joint has been at its torque limit."""

    def __init__(self, worlds: list[int], limits: np.ndarray, tick_dt: float) -> None:
        self.worlds = np.asarray(worlds, dtype=np.int64)
        self.limits = np.asarray(limits, np.float64)[:ARM]
        self.tick_dt = tick_dt
        self._since = np.full(len(worlds), -1, dtype=np.int64)  # tick when saturation began

    def check(self, snap: Snapshot) -> list[tuple[int, str]]:
        """(world, why) of each world that passes the limit now (once per episode)."""
        effort = np.abs(np.asarray(snap.effort[self.worlds, :ARM], np.float64))
        ratio = effort / self.limits
        hot = (ratio >= SATURATED).any(axis=1)
        out: list[tuple[int, str]] = []
        hold = max(1, round(HOLD_S / self.tick_dt))
        for i in np.flatnonzero(~hot):
            self._since[i] = -1
        for i in np.flatnonzero(hot):
            if self._since[i] < 0:
                self._since[i] = snap.tick
            elif snap.tick - self._since[i] == hold:
                j = int(np.argmax(ratio[i]))
                out.append(
                    (
                        int(self.worlds[i]),
                        f"joint {j} held at its torque limit ({effort[i, j]:.0f} of "
                        f"{self.limits[j]:.0f} N·m) for {HOLD_S:g} s: the arm is blocked",
                    )
                )
        return out
