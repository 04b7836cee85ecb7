"""The UR driver's action goals over rosbridge: accept, run, feed back, finish.

A goal comes as the ROS message in JSON shape (what rosbridge carries) and gets feedback and
the result back in the same shape; the rules are the ROS rulebook's (clients/ros_rules.py),
which the armfleet_ros node applies too, over the HTTP API:

- `FollowJointTrajectory` (on `scaled_joint_trajectory_controller` and
  `joint_trajectory_controller`): the goal becomes a `JointTrajectorySpec` (validated before
  anything moves; a bad goal is rejected with the validator's message) and runs on the
  trajectory manager; feedback is its desired / actual / error; the outcome maps to
  control_msgs' error codes (path / goal tolerance) and to SUCCEEDED, CANCELED or ABORTED.
  The controllers drive the six arm joints, as the UR driver's do.
- `GripperCommand` (on `robotiq_gripper_controller`): a finger_joint target, watched as
  ros2_controllers' GripperActionController does (with `allow_stalling`, as the Robotiq driver
  configures it): reached within `GOAL_TOLERANCE`, or stalled when the finger stops short of
  the goal for `STALL_TIMEOUT_S` of simulated time, which is what closing on the cube gives.
  `max_effort` is validated but not applied (the finger servo's force limit is the model's).

One thread of its own feeds back at `FEEDBACK_HZ` and watches grippers; it sleeps while no
goal is active. Trajectory outcomes arrive from the manager's listener on any thread and are
queued to that thread, so no lock of ours is ever held while the manager holds its own.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
import weakref
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from clients import ros_rules
from clients.ros_rules import (
    FEEDBACK_HZ,
    FJT_TYPE,
    GRIPPER_TYPE,
    SUCCESSFUL,
    FingerWatch,
    GoalRejected,
    Status,
)
from service.core.commands.control import Control
from service.core.commands.trajectory import AbortReason, TrajectoryStatus
from service.core.surface import SurfaceContext
from service.surfaces.rosbridge import topics
from service.surfaces.rosbridge.goal_msgs import (
    gripper_position,
    trajectory_feedback,
    trajectory_spec,
)

log = logging.getLogger("armfleet.ros")
_KEEP_EARLY = 4096


@dataclass
class Goal:
    """One accepted goal as its surface sees it; `result` is set when `status` is terminal."""

    action: str
    kind: str
    world: int
    accepted_at: float  # simulated seconds
    on_feedback: Callable[[Goal, dict[str, Any]], None]
    on_done: Callable[[Goal], None]
    status: Status = Status.EXECUTING
    key: Any = None  # the surface's id of the goal
    result: dict[str, Any] = field(default_factory=dict)
    traj_id: int | None = None
    finger: FingerWatch | None = None  # a gripper goal's reached / stalled rule
    effective_tick: int = 0  # the gripper target is in effect from this tick
    cancel_requested: bool = False


class GoalRunner:
    """Runs the action goals of one service; both surfaces submit to the same runner."""

    def __init__(self, ctx: SurfaceContext) -> None:
        self.loop = ctx.loop
        self.control = ctx.control
        self.spec = self.loop.spec
        self.arm = list(self.spec.names)[:6]
        self.finger = self.spec.index("finger_joint")
        self.tick_dt = self.loop.batch.tick_dt
        self._lock = threading.Lock()
        self._kick = threading.Event()  # a goal or an outcome arrived: the thread wakes
        self._active: list[Goal] = []
        self._by_traj: dict[int, Goal] = {}
        self._outcomes: queue.SimpleQueue[TrajectoryStatus] = queue.SimpleQueue()
        # outcomes of trajectories not (yet) known as goals: ours that ended before `submit`
        # stored their id, and other surfaces' (bounded: those are never asked for)
        self._early: OrderedDict[int, TrajectoryStatus] = OrderedDict()
        self.control.trajectories.add_listener(self._outcome)
        self._running = True
        self._thread = threading.Thread(target=self._run, name="armfleet-ros-goals", daemon=True)
        self._thread.start()

    def now(self) -> float:
        return topics.sim_seconds(self.loop.latest, self.tick_dt)

    # -- submit and cancel (any thread) -----------------------------------------------------

    def submit(
        self,
        action: str,
        kind: str,
        world: int,
        goal: dict[str, Any],
        source: str,
        on_feedback: Callable[[Goal, dict[str, Any]], None],
        on_done: Callable[[Goal], None],
        control: Control | None = None,
    ) -> Goal:
        """Validate and start a goal; GoalRejected (nothing moved) if it is invalid. `control`:
        the one acting for the goal's sender (Control.acting_for), checked per world."""
        control = control or self.control
        if not isinstance(goal, dict):
            raise GoalRejected(f"the goal must be a {kind} goal object")
        g = Goal(action, kind, world, self.now(), on_feedback, on_done)
        if kind == FJT_TYPE:
            spec = trajectory_spec(self.spec, self.arm, goal)
            # no lock of ours held: a preempted trajectory's listener runs in this thread
            (started,) = control.start_trajectory([world], spec, source)
            with self._lock:
                g.traj_id = started.id
                self._by_traj[started.id] = g
                early = self._early.pop(started.id, None)
                if early is not None:
                    self._outcomes.put(early)
        else:
            position = gripper_position(goal)
            done = control.command_targets(world, ["finger_joint"], [position], source)
            g.finger = FingerWatch(float(done.target[self.finger]))
            g.effective_tick = done.tick
        with self._lock:
            replaced = [
                old
                for old in self._active
                if old.kind == GRIPPER_TYPE == kind and old.world == world
            ]
            self._active.append(g)
        self._kick.set()
        for old in replaced:  # a newer gripper goal replaces the running one
            self._finish(old, Status.ABORTED, self._gripper_state(old, stalled=False))
        return g

    def cancel(self, g: Goal, source: str) -> bool:
        """Ask a goal to stop (it holds); False if it already finished."""
        with self._lock:
            if g.status.terminal or g.cancel_requested:
                return not g.status.terminal
            g.cancel_requested = True
            g.status = Status.CANCELING
        if g.kind == FJT_TYPE:
            self.control.cancel_trajectory([g.world], source)  # the outcome comes as CANCELLED
        else:
            state = self.loop.latest
            hold = float(state.position[g.world, self.finger])
            self.control.command_targets(g.world, ["finger_joint"], [hold], source)
            self._finish(g, Status.CANCELED, self._gripper_state(g, stalled=False))
        return True

    # -- outcomes ----------------------------------------------------------------------------

    def cancel_all(self, action: str, source: str) -> list[Goal]:
        """Cancel every running goal of `action` (a CancelGoal with an empty goal_info)."""
        with self._lock:
            running = [g for g in self._active if g.action == action]
        return [g for g in running if self.cancel(g, source)]

    def _outcome(self, status: TrajectoryStatus) -> None:
        """The manager's listener (any thread, maybe one inside `submit`): queue, wake."""
        self._outcomes.put(status)
        self._kick.set()

    def _trajectory_done(self, status: TrajectoryStatus) -> None:
        with self._lock:
            g = self._by_traj.pop(status.id, None)
            if g is None:
                self._early[status.id] = status
                while len(self._early) > _KEEP_EARLY:
                    self._early.popitem(last=False)
                return
        if status.reason is None:
            self._finish(g, Status.SUCCEEDED, {"error_code": SUCCESSFUL, "error_string": ""})
            return
        code = ros_rules.result_code(status.reason.value)
        end = Status.CANCELED if status.reason is AbortReason.CANCELLED else Status.ABORTED
        text = ros_rules.error_string(status.reason.value, status.detail)
        self._finish(g, end, {"error_code": code, "error_string": text})

    def _finish(self, g: Goal, status: Status, result: dict[str, Any]) -> None:
        with self._lock:
            if g not in self._active:
                return
            self._active.remove(g)
            g.status, g.result = status, result
        try:
            g.on_done(g)
        except Exception:
            log.exception("action result of %s could not be delivered", g.action)

    # -- the thread ---------------------------------------------------------------------------

    def _run(self) -> None:
        period = 1.0 / FEEDBACK_HZ
        while self._running:
            with self._lock:
                idle = not self._active
            if idle and self._outcomes.empty():
                self._kick.wait()  # nothing to feed back: sleep until a goal or an outcome
            self._kick.clear()
            started = time.monotonic()
            while not self._outcomes.empty():
                self._trajectory_done(self._outcomes.get())
            with self._lock:
                active = list(self._active)
            for g in active:
                try:
                    self._tend(g)
                except Exception:
                    log.exception("action goal on %s failed", g.action)
            self._kick.wait(max(0.0, started + period - time.monotonic()))

    def _tend(self, g: Goal) -> None:
        if g.kind == FJT_TYPE:
            status = self.control.trajectories.get(g.traj_id) if g.traj_id else None
            if status is not None and status.feedback_tick is not None:
                g.on_feedback(g, trajectory_feedback(status, self.tick_dt))
        else:
            self._tend_gripper(g)

    def _gripper_state(self, g: Goal, stalled: bool) -> dict[str, Any]:
        snap = self.loop.latest
        position = float(snap.position[g.world, self.finger])
        assert g.finger is not None  # a gripper goal's
        return {
            "position": position,
            "effort": float(snap.effort[g.world, self.finger]),
            "stalled": stalled,
            "reached_goal": g.finger.reached(position),
        }

    def _tend_gripper(self, g: Goal) -> None:
        snap = self.loop.latest
        if snap.tick < g.effective_tick:
            return  # the new target is not stepped yet
        assert g.finger is not None  # a gripper goal's
        now = topics.sim_seconds(snap, self.tick_dt)
        state = self._gripper_state(g, stalled=False)
        if g.finger.taken_over(float(snap.target[g.world, self.finger])):
            self._finish(g, Status.ABORTED, state)  # another command took the finger over
            return
        velocity = float(snap.velocity[g.world, self.finger])
        verdict = g.finger.verdict(now, state["position"], velocity)
        if verdict is not None:
            self._finish(g, Status.SUCCEEDED, {**state, "stalled": verdict == "stalled"})
            return
        g.on_feedback(g, state)

    def stop(self) -> None:
        self.control.trajectories.remove_listener(self._outcome)
        self._running = False
        self._kick.set()
        self._thread.join(timeout=5)


def runner_of(ctx: SurfaceContext) -> GoalRunner:
    """The service's one GoalRunner (made on first use; every rosbridge session, given the same
    context, share it)."""
    with _RUNNERS_LOCK:
        runner = _RUNNERS.get(ctx)
        if runner is None:
            runner = _RUNNERS[ctx] = GoalRunner(ctx)
        return runner


_RUNNERS_LOCK = threading.Lock()
_RUNNERS: weakref.WeakKeyDictionary[SurfaceContext, GoalRunner] = weakref.WeakKeyDictionary()
