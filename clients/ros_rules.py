"""The ROS rulebook: what a ROS message or goal means to armfleet, written once for both ROS faces.

armfleet is on the ROS graph twice: rosbridge inside the service (service/surfaces/rosbridge/)
and the armfleet_ros node (packaging/armfleet-ros), which runs on ROS's own Python with only the
client library installed. Each used to restate the rules, and their answers drifted apart (the
same bad JointState got two different sentences). Here is the one copy, in the client library
because that is the package both can import (the service may import the client's public
modules; the node has nothing else):

- the JointState rule (`joint_state`): every surface's, the service's HTTP and WebSocket
  commands included (service/core/sim/rules.py raises it as a 422);
- the actions: names, types, the feedback rate, control_msgs' result codes and which outcome
  gets which (`result_code`), the gripper goal's checks and GripperActionController's
  reached / stalled rule (`FingerWatch`);
- `BadMessage` (a refusal with the counter it goes to) and `RefusalCounter` (counts by kind,
  logs each kind at most once a second);
- `stamp`: seconds as builtin_interfaces Time;
- the safety mode's topic (`SAFETY_MODE_TOPIC`, `SAFETY_MODE_TYPE`, `safety_mode_number`).

Plain Python on plain values (no rclpy, no service), so both sides and the tests use it alike.
"""

from __future__ import annotations

import enum
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

ARM_JOINTS = 6  # the UR arm's joints come first in armfleet's joint order; finger_joint last
FINGER = "finger_joint"

# -- the safety mode -----------------------------------------------------------------------------
# Where UR's ROS 2 driver publishes it (its io_and_status_controller, under the robot's
# namespace), latched (transient local) and only when it changes. The driver's type,
# ur_dashboard_msgs/msg/SafetyMode, is `uint8 mode` with UR's numbers; it is not part of a ROS
# distribution's standard messages (ROS users without the UR driver have none), so both faces
# publish std_msgs/msg/UInt8 carrying the same number in `data`: any ROS 2 installation reads
# it, and the numbers are UR's (SafetyMode's constants: 1 NORMAL, 3 PROTECTIVE_STOP).
SAFETY_MODE_TOPIC = "io_and_status_controller/safety_mode"  # under a world's namespace
SAFETY_MODE_TYPE = "std_msgs/msg/UInt8"
SAFETY_MODES = {"NORMAL": 1, "PROTECTIVE_STOP": 3}  # armfleet's names → UR's numbers


def safety_mode_number(name: str) -> int:
    """UR's number of a safety mode armfleet names (a state's `safety_mode`)."""
    return SAFETY_MODES[name]


# -- actions ------------------------------------------------------------------------------------

FJT_TYPE = "control_msgs/action/FollowJointTrajectory"
GRIPPER_TYPE = "control_msgs/action/GripperCommand"
FJT_CONTROLLERS = ("scaled_joint_trajectory_controller", "joint_trajectory_controller")
GRIPPER_ACTION = "robotiq_gripper_controller/gripper_cmd"
ACTIONS = {
    **{f"{c}/follow_joint_trajectory": FJT_TYPE for c in FJT_CONTROLLERS},
    GRIPPER_ACTION: GRIPPER_TYPE,
}  # action name (under a world's namespace) → action type
FEEDBACK_HZ = 20.0  # joint_trajectory_controller's default action_monitor_rate
GOAL_TOLERANCE = 0.01  # rad: GripperActionController's default goal_tolerance
STALL_VELOCITY = 0.01  # rad/s: below this the finger counts as not moving
STALL_TIMEOUT_S = 0.2  # simulated seconds short of the goal without motion: stalled
# rad: a finger target this far from the goal's is another command's (the node reads targets
# from float32 frames, so nothing finer can be told apart on both faces)
TAKEN_OVER = 1e-5

# control_msgs FollowJointTrajectory result codes
SUCCESSFUL, INVALID_GOAL, INVALID_JOINTS = 0, -1, -2
PATH_TOLERANCE_VIOLATED, GOAL_TOLERANCE_VIOLATED = -4, -5
_CODES = {"path_tolerance": PATH_TOLERANCE_VIOLATED, "goal_tolerance": GOAL_TOLERANCE_VIOLATED}


class Status(enum.IntEnum):
    """action_msgs/GoalStatus values."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6

    @property
    def terminal(self) -> bool:
        return self >= Status.SUCCEEDED


def result_code(reason: str | None) -> int:
    """A trajectory's end (armfleet's abort reason; None: it succeeded) as control_msgs' error
    code: the tolerances have theirs, a cancel is not an error, the rest (preempted, manual
    override, reset, fault) is INVALID_GOAL with the reason in `error_string`."""
    if reason is None or reason == "cancelled":
        return SUCCESSFUL
    return _CODES.get(reason, INVALID_GOAL)


def error_string(reason: str | None, detail: str | None) -> str:
    """FollowJointTrajectory's `error_string`: the reason, and armfleet's words if any."""
    if reason is None:
        return ""
    return f"{reason}: {detail}" if detail else reason


class GoalRejected(ValueError):
    """The goal is invalid; nothing moved. The text says which field and why."""


def check_arm_joints(names: Sequence[str], arm: Sequence[str]) -> None:
    """The trajectory controllers drive the arm's joints only: BadMessage("unknown_joint")."""
    others = [n for n in names if n not in arm]
    if others:
        raise BadMessage(
            "unknown_joint",
            f"trajectory.joint_names: {others[0]!r} is not a joint of this controller "
            f"(joints: {', '.join(arm)}); the gripper has {GRIPPER_ACTION}",
        )


def gripper_goal(position: Any, max_effort: Any) -> float:
    """A GripperCommand goal's finger position [rad], or GoalRejected. `max_effort` is checked
    but not applied (the finger servo's force limit is the model's)."""
    for value, what in ((position, "position"), (max_effort, "max_effort")):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise GoalRejected(f"command.{what} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise GoalRejected(f"command.{what} must be finite, got {value}")
    if max_effort < 0:
        raise GoalRejected(f"command.max_effort must be >= 0, got {max_effort}")
    return float(position)


class FingerWatch:
    """GripperActionController's rule (with `allow_stalling`, as the Robotiq driver sets it) for
    one goal: reached within GOAL_TOLERANCE, or stalled when the finger stays short of the goal
    without moving for STALL_TIMEOUT_S of simulated time (what closing on the cube gives)."""

    def __init__(self, target: float) -> None:
        self.target = target  # the finger target armfleet took (clamped)
        self.moved_at = math.inf  # counted from the first tick with the new target

    def taken_over(self, target: float) -> bool:
        """Another command (a newer goal included) set the finger since: the goal aborts."""
        return abs(target - self.target) > TAKEN_OVER

    def reached(self, position: float) -> bool:
        return abs(position - self.target) < GOAL_TOLERANCE

    def verdict(self, now: float, position: float, velocity: float) -> str | None:
        """At simulated time `now`: "reached", "stalled" or None (keep going)."""
        self.moved_at = min(self.moved_at, now)
        if self.reached(position):
            return "reached"
        if abs(velocity) > STALL_VELOCITY:
            self.moved_at = now
        elif now - self.moved_at >= STALL_TIMEOUT_S:
            return "stalled"
        return None


# -- messages -----------------------------------------------------------------------------------


class BadMessage(ValueError):
    """A message that changes nothing; `kind` is the counter it goes to, `detail` says why."""

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(f"{kind}: {detail}")
        self.kind = kind
        self.detail = detail


class BadJointState(BadMessage):
    """The JointState rule broken; `field` is what is wrong (the service's 422 names it) and
    `detail` reads "field: message" on every face."""

    def __init__(self, kind: str, field: str, message: str) -> None:
        super().__init__(kind, f"{field}: {message}")
        self.field = field
        self.message = message


def _index(joints: Sequence[str], n: str) -> int | None:
    """A joint's index from its name or its index as a digit string (how JSON object keys
    name joints); None if it is neither."""
    if n.isascii() and n.isdigit():
        i = int(n)
        return i if i < len(joints) else None
    return list(joints).index(n) if n in joints else None


def joint_state(joints: Sequence[str], name: Any, position: Any) -> dict[int, float]:
    """A sensor_msgs/JointState command's (`name`, `position`) → {joint index: target}, or
    BadJointState. Names and positions pair up (a subset moves only those joints); with no
    names, one position per joint in joint order, as the seed's Isaac subscriber read them;
    every name a joint's name or its index as a digit string, no joint named twice (neither by
    the same name nor by its name and its index); every position a finite number. Velocity and
    effort are not commands; callers ignore them."""
    for field, value in (("name", name), ("position", position)):
        if not isinstance(value, list | tuple):
            raise BadJointState("bad_type", field, f"{field} must be an array, got {value!r}")
    if len(position) == 0:
        raise BadJointState("empty", "position", "position is empty; nothing to command")
    if len(name) == 0:
        if len(position) != len(joints):
            raise BadJointState(
                "length_mismatch",
                "position",
                f"without names, position needs all {len(joints)} joints (got {len(position)})",
            )
        name = list(joints)
    elif len(name) != len(position):
        raise BadJointState(
            "length_mismatch",
            "position",
            f"name and position must have equal lengths ({len(name)} names, "
            f"{len(position)} positions)",
        )
    out: dict[int, float] = {}
    for n, p in zip(name, position, strict=True):
        if not isinstance(n, str):
            raise BadJointState("bad_type", "name", f"a joint is named by a string, got {n!r}")
        index = _index(joints, n)
        if index is None:
            why = f"unknown joint {n!r}; joints are {list(joints)}"
            raise BadJointState("unknown_joint", "name", why)
        if index in out:  # the same name twice, or a name and that joint's index
            raise BadJointState("duplicate_joint", "name", f"joint {joints[index]!r} named twice")
        if isinstance(p, bool) or not isinstance(p, int | float):
            raise BadJointState("bad_type", f"position.{n}", f"must be a number, got {p!r}")
        if not math.isfinite(p):
            raise BadJointState("not_finite", f"position.{n}", f"{p} is not finite (no NaN or Inf)")
        out[index] = float(p)
    return out


def stamp(seconds: float) -> tuple[int, int]:
    """Seconds → builtin_interfaces Time (sec, nanosec), rounded to the nanosecond, never
    negative."""
    ns = max(0, round(seconds * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000


class RefusalCounter:
    """Refused messages and goals by kind (thread-safe); each kind logged at most once per
    `interval` seconds. A flood of bad messages (a misconfigured node at 1 kHz) would otherwise
    fill the log; the counts stay exact (`GET /v1/ros` shows both faces')."""

    def __init__(self, source: str, warn: Callable[[str], Any], interval: float = 1.0) -> None:
        self._source = source  # "rosbridge", "armfleet_ros"
        self._warn = warn  # a logger's `warning`
        self._interval = interval
        self._lock = threading.Lock()
        self._counts: dict[str, int] = {}
        self._last_log: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def report(self, kind: str, where: str, detail: str) -> None:
        now = time.monotonic()
        with self._lock:
            self._counts[kind] = self._counts.get(kind, 0) + 1
            if now - self._last_log.get(kind, -math.inf) < self._interval:
                self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
                return
            self._last_log[kind] = now
            hidden = self._suppressed.pop(kind, 0)
        more = f" ({hidden} more of this kind since the last log line)" if hidden else ""
        self._warn(f"{self._source}: refused on {where}: {kind}: {detail}{more}")

    def counts(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self._counts.values())
