"""The clearance watch: every world's commanded arm targets against the scene's fixed
obstacles, on every surface's commands (REST, WebSocket, ROS, rosbridge, UR programs, replay).

Why here, beside the commands, and not in a surface: a target is a target whichever surface
sent it, and the world's safety mode is the core's (core/sim/safety.py), so the watch that
raises it is the core's too. The kinematics are core/kinematics/clearance.py (it says why the
commanded target and not the contact force); this module decides *when* and *whom* to stop.

When: after every tick, on the sim thread, on the targets as of every accepted command
(`pending_targets`: what the next tick will be handed, the running trajectories' latest samples
included), for the worlds whose arm targets changed since the last check; all of them batched
in one call of `Clearance.depth`, but for those it cannot have brought that near: a point of
the arm moves at most `Clearance.reach[j]` per radian of joint j (`finger_reach` of the
gripper), and a distance to a convex obstacle changes by no more than the point moved, so a
world last measured `d` clear of everything is measured again only once its targets (and its
gripper) moved enough to close that gap (a world stepping along a trajectory far from the
table is measured every few ticks, one next to it every tick; exact, never a miss). A world
whose new target reaches deeper than `ALLOWED_DEPTH`
into an obstacle *and* deeper than its last checked target is protective-stopped: the
`ProtectiveStop` command holds the arm where it is (its actual angles at the latest snapshot)
and stops its trajectory in the same step as the mode changes, before the next tick takes the
target. "Deeper than the last" lets the arm be driven back out after an unlock (never further
in) from a pose the stop held it in.
"""

from __future__ import annotations

import logging

import numpy as np

from service.core.commands.control import Control
from service.core.commands.safety_stop import ProtectiveStop
from service.core.errors import ArmfleetError
from service.core.kinematics.clearance import ALLOWED_DEPTH, Clearance
from service.core.kinematics.tools import tools_of
from service.core.sim.batch import Batch
from service.core.sim.loop_types import SnapshotSink
from service.core.sim.safety import NORMAL

__all__ = ["SOURCE", "ClearanceWatch", "due", "watch_clearance"]

log = logging.getLogger("armfleet.safety")
SOURCE = "safety"  # the source label of the stops it raises (metrics, recordings)
ARM = 6  # the arm's joints come first; the gripper's finger_joint is next


class ClearanceWatch(SnapshotSink):
    """Stops every world whose commanded target goes into a fixed obstacle (module docstring)."""

    def __init__(self, control: Control, clearance: Clearance) -> None:
        self.control = control
        self.clearance = clearance
        nworld = control.nworld
        self._last = np.full((nworld, ARM), np.nan)  # arm targets at the last check
        self._depth = np.full(nworld, -np.inf)  # their depth [m]
        self._opening = np.zeros(nworld)  # the gripper's opening then [rad]
        self.checked = 0  # worlds measured so far
        self.spared = 0  # worlds whose targets changed but could not have come near enough
        # The desk's change count at the last look, and whether some world's targets then
        # differed from its last measured ones (spared: due again as its gripper opens).
        self._looked = -1
        self._unmeasured = False

    def on_tick(self, batch: Batch, now: float) -> None:
        loop = self.control.loop
        changes = loop.commands.changes  # before the targets: a change after it is seen next
        if changes == self._looked and not self._unmeasured:
            # Nothing staged since the last look and every world measured at its targets: the
            # comparison below would find nothing (at 16,384 worlds it cost the sim thread
            # ~0.8 ms a tick on an H200's host, a quarter of the tick: bench/results/issue39/gpu6).
            return
        self._looked = changes
        arm = loop.commands.pending_targets(slice(None))[:, :ARM]
        changed = (arm != self._last).any(axis=1)
        self._unmeasured = False
        if not changed.any():
            return
        latest = loop.latest
        gripper = latest.position.shape[1] > ARM  # as it is (clearance.py says why)
        opening = np.asarray(latest.position[:, ARM], np.float64) if gripper else self._opening
        c = self.clearance
        since = (self._last, self._opening, self._depth)
        moved = np.flatnonzero(changed & due(c, arm, opening, *since))
        spared = int(changed.sum()) - int(moved.size)
        self.spared += spared
        self._unmeasured = spared > 0
        if moved.size == 0:
            return
        depth, geom, obstacle = self.clearance.depth(arm[moved], opening[moved])
        self.checked += int(moved.size)
        deeper = (depth > ALLOWED_DEPTH) & (depth > self._depth[moved])
        self._last[moved] = arm[moved]
        self._depth[moved] = depth
        self._opening[moved] = opening[moved]
        if not deeper.any():
            return
        safety = loop.safety
        for i in np.flatnonzero(deeper).tolist():
            world = int(moved[i])
            if safety.mode(world) != NORMAL:
                continue
            c = self.clearance
            why = (
                f"the commanded pose takes {c.geom_names[geom[i]]} {depth[i] * 1e3:.1f} mm into "
                f"{c.obstacle_names[obstacle[i]]} (more than {ALLOWED_DEPTH * 1e3:g} mm): the "
                "arm would go through it"
            )
            held = np.asarray(latest.position[world, :ARM], np.float64)
            try:
                self.control.run(ProtectiveStop.create(self.control, world, held, why), SOURCE)
            except ArmfleetError:  # never lose the watch over one world's stop
                log.exception("world %d: the protective stop failed", world)


def due(
    clearance: Clearance,
    arm: np.ndarray,
    opening: np.ndarray,
    last: np.ndarray,
    last_opening: np.ndarray,
    depth: np.ndarray,
) -> np.ndarray:
    """Which worlds (n,) bool may have come within ALLOWED_DEPTH of an obstacle since they were
    last measured `depth` (n,) clear at arm targets `last` (n, 6) and gripper `last_opening`
    (n,): all whose joints moved enough to close that gap (module docstring); a world never
    measured (nan) is due."""
    came = np.abs(arm - last) @ clearance.reach
    came += clearance.finger_reach * np.abs(opening - last_opening)
    return ~(came < ALLOWED_DEPTH - depth)


def watch_clearance(control: Control) -> ClearanceWatch | None:
    """The watch of the served cell, added to the loop's sinks; None (nothing watched, said in
    the log) when the arm is not UR's DH chain or nothing fixed collides with it."""
    loop = control.loop
    try:
        kin = tools_of(loop).kin
    except ArmfleetError as exc:
        log.info("no clearance watch: %s", exc)
        return None
    names = control.spec.names
    finger = names[ARM] if len(names) > ARM else None
    clearance = Clearance.of_model(loop.batch.robot.mjm, names[:ARM], kin, finger)
    if clearance is None:
        log.info("no clearance watch: nothing fixed in the scene collides with the arm")
        return None
    watch = ClearanceWatch(control, clearance)
    loop.listeners.add_sink(watch)
    log.info(
        "clearance watch: %d arm geoms against %s (a commanded target more than %g mm into "
        "one is a protective stop)",
        len(clearance.geom_names),
        ", ".join(clearance.obstacle_names),
        ALLOWED_DEPTH * 1e3,
    )
    return watch
