"""A move in joint space (UR's movej) as joint samples with velocities, for the trajectory runner.

Every joint starts and stops together, as a UR controller moves them: the joint that needs the
longest at speed v and acceleration a (each joint's speed also held under its own limit, the
UR10e's 120 °/s for base and shoulder and 180 °/s for the others) sets the duration, and all
joints follow the same path fraction s(t) of it, so the arm moves on the straight line in
joint space from start to goal. The speed profile is `line.profile` (half-sine ramps of peak
acceleration a), whose ramps the position servos follow more closely than UR's trapezoid.

A move that would need a joint faster than its limit, or a goal outside a joint's range, is
refused before anything moves (BadCommand naming the field and the limit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from service.core.errors import BadCommand
from service.core.kinematics.line import MAX_SAMPLES, SAMPLE_DT, duration, profile, refuse_first

__all__ = ["UR10E_JOINT_SPEED", "JointPlan", "plan_joint_move", "plan_stop"]

# rad/s: base, shoulder 120 °/s; elbow and wrists 180 °/s (UR10e manual via joint_limits.yaml)
UR10E_JOINT_SPEED = np.array([2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416])
_SLACK = 1.02
_STILL = 1e-9


@dataclass(frozen=True)
class JointPlan:
    """times (N,) [s] after the start, q (N, 6) [rad], qd (N, 6) [rad/s]; the last sample is
    the goal, at rest."""

    times: np.ndarray
    q: np.ndarray
    qd: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.times[-1])


def plan_joint_move(
    q_start: np.ndarray,
    goal: np.ndarray,
    speed: float,
    accel: float,
    limits: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    names: tuple[str, ...],
) -> JointPlan:
    """Samples of a synchronised joint move from q_start (6,) to goal (6,) at `speed` [rad/s]
    and `accel` [rad/s²], no joint faster than `limits` (6,); goal inside [lower, upper]."""
    q_start, goal = np.asarray(q_start, np.float64), np.asarray(goal, np.float64)
    for j in range(6):
        if not lower[j] <= goal[j] <= upper[j]:
            raise BadCommand(
                "q",
                f"{names[j]} goal {goal[j]:.6g} rad is outside its range "
                f"[{lower[j]:.6g}, {upper[j]:.6g}]",
            )
    step = goal - q_start
    dist = np.abs(step)
    if dist.max() <= _STILL:
        return JointPlan(np.array([SAMPLE_DT]), goal[None], np.zeros((1, 6)))
    v_joint = np.minimum(speed, limits)
    times_each = [
        duration(float(d), float(v), accel) if d > _STILL else 0.0
        for d, v in zip(dist, v_joint, strict=True)
    ]
    lead = int(np.argmax(times_each))
    total = times_each[lead]
    n = min(MAX_SAMPLES, max(2, math.ceil(total / SAMPLE_DT)))
    times = total * np.arange(1, n + 1) / n
    s, rate = profile(float(dist[lead]), float(v_joint[lead]), accel, times)
    frac, frac_rate = s / dist[lead], rate / dist[lead]
    q = q_start + frac[:, None] * step
    qd = frac_rate[:, None] * step
    q[-1], qd[-1] = goal, 0.0
    refuse_first(
        np.abs(qd) > limits * _SLACK,
        "speed",
        lambda k, j: (
            f"{names[j]} would turn at {abs(qd[k, j]):.4g} rad/s, over its limit of "
            f"{limits[j]:.4g} rad/s"
        ),
    )
    return JointPlan(times, q, qd)


def plan_stop(
    q: np.ndarray, qd: np.ndarray, decel: float, lower: np.ndarray, upper: np.ndarray
) -> JointPlan:
    """Samples that bring joints at q (6,) moving at qd (6,) to rest, every joint decelerating
    together in joint space at `decel` [rad/s²] (UR's stopj): the stop point lies
    |qd|²/(2 decel) on, inside the joint ranges."""
    q, qd = np.asarray(q, np.float64), np.asarray(qd, np.float64)
    speed = float(np.abs(qd).max())
    if speed < 1e-6:
        return JointPlan(np.array([SAMPLE_DT]), q[None], np.zeros((1, 6)))
    total = speed / decel
    n = min(MAX_SAMPLES, max(2, math.ceil(total / SAMPLE_DT)))
    times = total * np.arange(1, n + 1) / n
    fall = 1.0 - times / total  # speed as a fraction of the start's, linearly to 0
    travelled = times - times**2 / (2 * total)  # ∫ fall dt
    out_q = np.clip(q + travelled[:, None] * qd, lower, upper)
    out_qd = fall[:, None] * qd
    out_qd[-1] = 0.0
    return JointPlan(times, out_q, out_qd)
