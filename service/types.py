"""Data structures shared by the engine, the loop and the API.

They are plain frozen dataclasses over numpy arrays so that the engine (which knows MuJoCo Warp)
and the API (which knows JSON) meet on something neither owns.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class JointSpec:
    """One commanded joint as the outside world sees it.

    name: joint name, as in sensor_msgs/JointState and the MJCF
    lower, upper: joint range [rad]; targets are clamped to it
    home: value in the `home` keyframe [rad]
    velocity_limit: rated maximum speed [rad/s] (informative; MuJoCo does not enforce it)
    effort_limit: actuator force limit [N·m]
    """

    name: str
    lower: float
    upper: float
    home: float
    velocity_limit: float
    effort_limit: float


def _frozen(values: list[float]) -> np.ndarray:
    out = np.array(values, dtype=np.float64)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class RobotSpec:
    """The commanded joints of the robot, in command order (six arm joints, then finger_joint)."""

    name: str
    joints: tuple[JointSpec, ...]

    # Derived once: every command clamps against these. Read-only so that sharing is safe.
    @cached_property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @cached_property
    def lower(self) -> np.ndarray:
        return _frozen([j.lower for j in self.joints])

    @cached_property
    def upper(self) -> np.ndarray:
        return _frozen([j.upper for j in self.joints])

    @cached_property
    def home(self) -> np.ndarray:
        return _frozen([j.home for j in self.joints])

    def index(self, joint: str | int) -> int:
        """Joint index from a name or an index; raises KeyError naming the valid choices."""
        if isinstance(joint, int) and not isinstance(joint, bool):
            if 0 <= joint < len(self.joints):
                return joint
            raise KeyError(f"joint index {joint} out of range 0..{len(self.joints) - 1}")
        for i, j in enumerate(self.joints):
            if j.name == joint:
                return i
        raise KeyError(f"unknown joint {joint!r}; joints are {self.names}")


@dataclass(frozen=True)
class Snapshot:
    """One consistent view of every world at the end of one control tick.

    tick: control ticks completed by the batch since start
    sim_time: per-world simulated seconds since that world's last reset        (nworld,)
    position, velocity: the commanded joints' qpos [rad] and qvel [rad/s]        (nworld, 7)
    effort: actuator torque on each commanded joint [N·m], gravity comp included (nworld, 7)
    target: position targets in effect during this tick [rad]                  (nworld, 7)
    flange_pos: flange site position in the world frame [m]                    (nworld, 3)
    flange_quat: flange site orientation, quaternion w x y z                   (nworld, 4)
    faults: how often each world has been reset for NaN or capacity overflow   (nworld,)
    body_pos: every body's origin in the world frame [m], float32               (nworld, nbody, 3)
    body_quat: every body's orientation, quaternion w x y z, float32           (nworld, nbody, 4)
        (bodies in MjModel order, 0 = world; what viewers draw, see GET /v1/scene)
    """

    tick: int
    sim_time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    target: np.ndarray
    flange_pos: np.ndarray
    flange_quat: np.ndarray
    faults: np.ndarray
    body_pos: np.ndarray
    body_quat: np.ndarray

    @property
    def nworld(self) -> int:
        return int(self.position.shape[0])


class Mode(enum.StrEnum):
    """How the loop advances time."""

    REALTIME = "realtime"  # paced to the wall clock; falls behind honestly (RTF < 1), no bursts
    FAST = "fast"  # as fast as the machine allows
    PAUSED = "paused"  # only on an explicit step request
