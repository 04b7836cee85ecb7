"""The UR driver's and the Robotiq driver's action servers, per world, on armfleet's API.

- FollowJointTrajectory (`scaled_joint_trajectory_controller`, `joint_trajectory_controller`):
  a goal is started on armfleet's trajectory core (`POST /v1/worlds/{w}/trajectory`) inside the
  goal callback, so an invalid one is rejected at `send_goal` with armfleet's reason and nothing
  moves; feedback polls `GET /v1/trajectories/{id}` at 20 Hz; the outcome maps to control_msgs'
  error codes (path -4, goal tolerance -5, preempted / manual override / reset / fault -1 with
  the reason in `error_string`); cancel is `DELETE .../trajectory` and the arm holds.
- GripperCommand (`robotiq_gripper_controller/gripper_cmd`): a target on `finger_joint`
  (clamped by armfleet), tended from the state stream as GripperActionController does:
  reached within 0.01 rad, or stalled after 0.2 simulated seconds without motion; another
  command on the finger (a newer goal included) aborts it; cancel holds the finger.

Execute callbacks block (one executor thread per running goal): rclpy's coroutine callbacks
behave differently across distributions, threads do not.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

from control_msgs.action import FollowJointTrajectory, GripperCommand
from rclpy.action import ActionServer, CancelResponse, GoalResponse

from armfleet_ros.convert import trajectory_body
from clients import ros_rules
from clients import trajectory as tj
from clients.errors import ArmfleetError
from clients.ros_rules import (
    ARM_JOINTS,
    FEEDBACK_HZ,
    FINGER,
    FJT_CONTROLLERS,
    GRIPPER_ACTION,
    BadMessage,
    FingerWatch,
    GoalRejected,
    stamp,
)


def _fill_point(point: Any, values: Any, elapsed: float) -> None:
    point.positions = [0.0 if math.isnan(v) else float(v) for v in values]
    sec, nanosec = stamp(elapsed)
    point.time_from_start.sec, point.time_from_start.nanosec = sec, nanosec


def _server(part: Any, kind: Any, name: str, handler: Any) -> ActionServer:
    """An action server of the node's part (its node and callback group) for `handler`'s
    goals: every goal may be cancelled (the handler stops the world where it is)."""
    return ActionServer(
        part.servers,
        kind,
        name,
        execute_callback=handler._execute,
        goal_callback=handler._goal,
        cancel_callback=lambda _h: CancelResponse.ACCEPT,
        callback_group=part.group,
    )


TRAJECTORY_ACTIONS = tuple(f"{c}/follow_joint_trajectory" for c in FJT_CONTROLLERS)


class TrajectoryAction:
    """The FollowJointTrajectory server of one world under one controller's name
    (`name`: one of TRAJECTORY_ACTIONS)."""

    def __init__(self, owner: Any, world: int, ns: str, part: Any, name: str) -> None:
        self.owner, self.world = owner, world
        self._started: dict[int, int] = {}  # id(goal message) → trajectory id
        self._lock = threading.Lock()
        self.server = _server(part, FollowJointTrajectory, f"{ns}/{name}", self)

    def _goal(self, goal: Any) -> GoalResponse:
        where = f"world {self.world} follow_joint_trajectory"
        arm = self.owner.joints[:ARM_JOINTS]
        try:
            ros_rules.check_arm_joints(list(goal.trajectory.joint_names), arm)
            body = trajectory_body(
                goal.trajectory, goal.path_tolerance, goal.goal_tolerance, goal.goal_time_tolerance
            )
            started = self.owner.http.call(tj.start_call(self.world, body))
        except BadMessage as exc:
            self.owner.bad.report("rejected_goal", where, exc.detail)
            return GoalResponse.REJECT
        except ArmfleetError as exc:
            self.owner.bad.report("rejected_goal", where, str(exc))
            return GoalResponse.REJECT
        with self._lock:
            self._started[id(goal)] = started.id
        return GoalResponse.ACCEPT

    def _execute(self, handle: Any) -> Any:
        with self._lock:
            traj_id = self._started.pop(id(handle.request))
        http, dt = self.owner.http, self.owner.tick_dt
        result = FollowJointTrajectory.Result()
        while True:
            if handle.is_cancel_requested:
                status = http.call(tj.by_id_call(traj_id))
                if not status.done:
                    http.call(tj.cancel_call(self.world))
                    status = http.call(tj.by_id_call(traj_id, 2.0))
                if status.reason == "cancelled" or not status.done:
                    handle.canceled()
                    result.error_string = "cancelled"
                    return result
            else:
                status = http.call(tj.by_id_call(traj_id, 1.0 / FEEDBACK_HZ))
            if status.done:
                break
            if status.actual.size:
                handle.publish_feedback(self._feedback(status, dt))
        if status.succeeded:
            handle.succeed()
            return result
        reason = status.reason or "aborted"
        result.error_code = ros_rules.result_code(reason)
        result.error_string = ros_rules.error_string(reason, status.detail)
        if reason == "cancelled":
            handle.canceled()
        else:
            handle.abort()
        return result

    @staticmethod
    def _feedback(status: Any, dt: float) -> Any:
        fb = FollowJointTrajectory.Feedback()
        sec, nanosec = stamp(status.tick * dt)
        fb.header.stamp.sec, fb.header.stamp.nanosec = sec, nanosec
        fb.joint_names = list(status.joint_names)
        elapsed = max(0.0, (status.tick - status.start_tick + 1) * dt)
        _fill_point(fb.desired, status.desired, elapsed)
        _fill_point(fb.actual, status.actual, elapsed)
        _fill_point(fb.error, status.error, elapsed)
        return fb


class GripperAction:
    """The Robotiq GripperCommand server of one world."""

    def __init__(self, owner: Any, world: int, ns: str, part: Any) -> None:
        self.owner, self.world = owner, world
        self.finger = owner.joints.index(FINGER)
        self.server = _server(part, GripperCommand, f"{ns}/{GRIPPER_ACTION}", self)

    def _goal(self, goal: Any) -> GoalResponse:
        try:
            ros_rules.gripper_goal(goal.command.position, goal.command.max_effort)
        except GoalRejected as exc:
            self.owner.bad.report("rejected_goal", f"world {self.world} gripper_cmd", str(exc))
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _execute(self, handle: Any) -> Any:
        link = self.owner.link
        try:
            ack = link.set_targets(self.world, {FINGER: handle.request.command.position})
            ack = ack.result(timeout=5.0)
        except Exception as exc:
            self.owner.bad.report("rejected_goal", f"world {self.world} gripper_cmd", str(exc))
            handle.abort()
            return self._result(False)
        watch = FingerWatch(float(ack.target[self.finger]))
        period = 1.0 / FEEDBACK_HZ
        while True:
            time.sleep(period)
            st = link.latest
            if st is None or st.tick < ack.tick:
                continue  # the new target is not stepped yet
            row = st.row(self.world)
            now = st.tick * self.owner.tick_dt
            position = float(st.position[row, self.finger])
            if handle.is_cancel_requested:
                link.set_targets(self.world, {FINGER: position})
                handle.canceled()
                return self._result(False, position, st.effort[row, self.finger])
            if watch.taken_over(float(st.target[row, self.finger])):
                handle.abort()  # another command (or a newer goal) took the finger over
                return self._result(False, position, st.effort[row, self.finger])
            verdict = watch.verdict(now, position, float(st.velocity[row, self.finger]))
            if verdict is not None:
                handle.succeed()
                stalled = verdict == "stalled"
                return self._result(stalled, position, st.effort[row, self.finger], not stalled)
            fb = GripperCommand.Feedback()
            fb.position, fb.effort = position, float(st.effort[row, self.finger])
            fb.stalled, fb.reached_goal = False, False
            handle.publish_feedback(fb)

    @staticmethod
    def _result(
        stalled: bool, position: float = 0.0, effort: float = 0.0, reached: bool = False
    ) -> Any:
        result = GripperCommand.Result()
        result.position, result.effort = float(position), float(effort)
        result.stalled, result.reached_goal = stalled, reached
        return result
