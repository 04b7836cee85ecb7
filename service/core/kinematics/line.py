"""A straight TCP line (UR's moveL) as joint samples with velocities, for the trajectory runner.

The TCP moves on the segment from its pose at the start q to the goal pose, its orientation
turning about one fixed axis in step (R(s) = exp(s w) R0, w the rotation vector of R1 R0ᵀ),
along a speed profile with smooth ramps (speed v, peak acceleration a; for a pure rotation
they are read as rad/s and rad/s², as UR does). Each sample's q is the closed-form solution
nearest the previous one and its velocity is J(q)⁻¹ × the TCP twist; the trajectory runner
feeds that velocity forward (ctrl = q + kv/kp × q̇), which takes away the position servos' lag
behind a moving target (kv/kp × speed), and with `lag` each sample's position leads by what
the servos need to accelerate the arm (M(q) q̈ / kp, servo.py): the acceleration feed-forward.

Why the samples fall on the loop's ticks (`tick_dt`; every tick, up to `MAX_SAMPLES`): the
runner interpolates between samples with cubic (Hermite) segments whose slope averages the
change of the *led* position over the segment, so between samples the velocity fed forward
also carries the lead's rate of change, kv/kp × d(M q̈ / kp)/dt: a force in proportion to the
jerk, different for every joint, which took the TCP 2 mm off the line at the end of a line at
1.2 m/s² (samples 8 ms apart). A sample on a tick is read as it is, position and velocity, so
the servos get exactly q + M q̈/kp + kv/kp × q̇: 0.09 mm off the line in the same move
(native MuJoCo at 60, 125 and 500 Hz). A line longer than `MAX_SAMPLES` ticks keeps a sample
on every tick of its ramps, where the lead changes, and spaces those of its cruise, where it
hardly does.

A line that no joint configuration can follow is refused before anything moves (BadCommand,
422): the goal out of reach or outside the joint ranges (`pose`), a sample out of reach or the
line passing a singularity, where a joint would have to turn faster than its limit (`speed`:
lower it, or move around the singularity).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from service.core.errors import BadCommand
from service.core.kinematics.pose import (
    matrix_to_rotvec,
    pose_to_matrix,
    rotvec_to_matrix,
)
from service.core.kinematics.servo import ServoLag
from service.core.kinematics.ur import TWO_PI, URKinematics

__all__ = ["MAX_SAMPLES", "SAMPLE_DT", "LinePlan", "plan_line", "profile"]

SAMPLE_DT = 0.008  # s between samples where no tick is given (a UR controller's is 0.002 s)
MAX_SAMPLES = 1000  # the trajectory runner's MAX_POINTS
_STILL = 1e-9  # m or rad: a line shorter than this is no move
_SPEED_SLACK = 1.02  # a sample's joint speed may pass the limit by this factor (rounding)


@dataclass(frozen=True)
class LinePlan:
    """times (N,) [s] after the start, q (N, 6) [rad], qd (N, 6) [rad/s]; the last sample is
    the goal, at rest. length [m] and angle [rad] of the move; duration = times[-1]."""

    times: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    length: float
    angle: float

    @property
    def duration(self) -> float:
        return float(self.times[-1])


def profile(distance: float, v: float, a: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position along the path and its rate at times t: speed v, reached and left on
    half-sine acceleration ramps whose peak is a (a triangle when `distance` is too short
    to reach v). Why not UR's plain trapezoid: its steps of acceleration jolt the servos, and
    their lag behind a step differs from joint to joint, which takes the TCP off the line."""
    v = min(v, math.sqrt(2 * a * distance / math.pi))
    ramp = math.pi * v / (2 * a)
    total = distance / v + ramp
    t = np.clip(t, 0.0, total)
    w = math.pi / ramp

    def up(x: np.ndarray) -> np.ndarray:  # the distance covered x s into a ramp up
        return v / 2 * (x - np.sin(w * x) / w)

    up_part, down_part = t < ramp, t > total - ramp
    s = np.where(up_part, up(t), v * ramp / 2 + v * (t - ramp))
    s = np.where(down_part, distance - up(total - t), s)
    rate = np.where(up_part, v / 2 * (1 - np.cos(w * t)), v)
    rate = np.where(down_part, v / 2 * (1 - np.cos(w * (total - t))), rate)
    return s, rate


def _peak(distance: float, v: float, a: float) -> float:
    """The speed `profile` reaches over `distance` (v, or less on a short one)."""
    return min(v, math.sqrt(2 * a * distance / math.pi))


def sample_times(total: float, ramp: float, tick: float) -> np.ndarray:
    """Times [s] of a plan's samples: multiples of `tick`, the last at or just after `total`;
    every tick, or, over MAX_SAMPLES, every tick of the two ramps (`ramp` s each) and evenly
    spaced ticks between them (evenly spaced throughout if the ramps alone are too many)."""
    n = max(2, math.ceil(total / tick - 1e-9))
    if n <= MAX_SAMPLES:
        return tick * np.arange(1, n + 1)
    r = math.ceil(ramp / tick)
    room = MAX_SAMPLES - 2 * r - 2
    ticks = np.zeros(0)
    if room >= 1:
        stride = math.ceil((n - 2 * r) / room)
        ticks = np.r_[np.arange(1, r + 1), np.arange(r + stride, n - r, stride), n - r : n + 1]
    if not 0 < len(ticks) <= MAX_SAMPLES:
        stride = math.ceil(n / (MAX_SAMPLES - 1))
        ticks = np.r_[np.arange(stride, n, stride), n]
    return tick * np.unique(ticks).astype(np.float64)


def duration(distance: float, v: float, a: float) -> float:
    """How long `profile` takes over `distance`."""
    v = min(v, math.sqrt(2 * a * distance / math.pi))
    return distance / v + math.pi * v / (2 * a)


def refuse_first(over: np.ndarray, field: str, why: Callable[[int, int], str]) -> None:
    """Refuse a plan at the first (sample k, joint j) where `over` holds: BadCommand(`field`,
    `why(k, j)`), so that the reply names the joint, the limit and where the plan breaks it."""
    if over.any():
        k, j = (int(x) for x in np.argwhere(over)[0])
        raise BadCommand(field, why(k, j))


def plan_line(
    kin: URKinematics,
    q_start: np.ndarray,
    goal: np.ndarray,
    tcp: np.ndarray,
    speed: float,
    accel: float,
    joint_speed: np.ndarray,
    names: tuple[str, ...],
    lag: ServoLag | None = None,
    tick_dt: float = SAMPLE_DT,
) -> LinePlan:
    """The samples of a line from the TCP pose at q_start (6,) to `goal` (6,), both in the base
    frame with the TCP offset `tcp` (6,); `joint_speed` (6,) the limits [rad/s] named `names`.
    With `lag`, the samples' positions lead by the servos' acceleration lag (servo.py): `q` is
    then what the servos are given, the line's own joint path being q - lead. The samples fall
    on multiples of `tick_dt` [s], the loop's tick (see the module docstring)."""
    q_start = np.asarray(q_start, dtype=np.float64)
    first = kin.ik(goal[None], q_start[None], tcp[None])
    if not first.ok[0]:
        raise BadCommand("pose", f"no joint configuration reaches it ({first.why(0)})")
    t0, t1 = kin.tcp(q_start[None], tcp[None])[0], pose_to_matrix(goal)
    step = t1[:3, 3] - t0[:3, 3]
    turn = matrix_to_rotvec(t1[:3, :3] @ t0[:3, :3].T)
    length, angle = float(np.linalg.norm(step)), float(np.linalg.norm(turn))
    distance = length if length > _STILL else angle
    if distance <= _STILL:  # already there: hold the start
        return LinePlan(np.array([SAMPLE_DT]), q_start[None], np.zeros((1, 6)), length, angle)
    total = duration(distance, speed, accel)
    times = sample_times(total, total - distance / _peak(distance, speed, accel), tick_dt)
    n = len(times)
    s, rate = profile(distance, speed, accel, times)
    s, rate = s / distance, rate / distance  # fraction of the line, and its rate
    poses = np.empty((n, 4, 4))
    poses[:, :3, :3] = rotvec_to_matrix(s[:, None] * turn) @ t0[:3, :3]
    poses[:, :3, 3] = t0[:3, 3] + s[:, None] * step
    poses[:, 3] = (0.0, 0.0, 0.0, 1.0)
    poses[-1] = t1
    sols, valid = kin.solutions(poses, tcp, np.full(n, q_start[5]))
    q = _follow(sols, valid, q_start, s, kin, names)
    twist = np.concatenate([rate[:, None] * step, rate[:, None] * turn], axis=1)
    qd = _joint_speeds(kin, q, tcp, twist)
    qd[-1] = 0.0
    _check_speeds(q_start, q, qd, times, joint_speed, names, s)
    if lag is not None:
        qdd = np.gradient(np.concatenate([np.zeros((1, 6)), qd]), np.r_[0.0, times], axis=0)
        lead = lag.offset(q, qdd[1:])
        lead[-1] = 0.0  # the goal itself, at rest
        q = q + lead
    return LinePlan(times, q, qd, length, angle)


def _follow(
    sols: np.ndarray,
    valid: np.ndarray,
    q_start: np.ndarray,
    s: np.ndarray,
    kin: URKinematics,
    names: tuple[str, ...],
) -> np.ndarray:
    """Each sample's solution nearest the previous sample's (the start's for the first)."""
    out = np.empty((len(sols), 6))
    prev = q_start
    for k in range(len(sols)):
        if not valid[k].any():
            raise BadCommand("pose", f"the line leaves the arm's reach at {100 * s[k]:.0f}% of it")
        cand = sols[k][valid[k]]
        cand = cand + TWO_PI * np.round((prev - cand) / TWO_PI)
        prev = out[k] = cand[np.argmin(((cand - prev) ** 2).sum(axis=1))]
    refuse_first(
        (out < kin.lower) | (out > kin.upper),
        "pose",
        lambda k, j: (
            f"the line takes {names[j]} to {out[k, j]:.4g} rad, outside its range "
            f"[{kin.lower[j]:.6g}, {kin.upper[j]:.6g}], at {100 * s[k]:.0f}% of it"
        ),
    )
    return out


def _joint_speeds(
    kin: URKinematics, q: np.ndarray, tcp: np.ndarray, twist: np.ndarray
) -> np.ndarray:
    jac = kin.jacobian(q, np.broadcast_to(tcp, (len(q), 6)))
    try:
        return np.linalg.solve(jac, twist[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return np.stack(
            [np.linalg.lstsq(j, t, rcond=None)[0] for j, t in zip(jac, twist, strict=True)]
        )


def _check_speeds(
    q_start: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    times: np.ndarray,
    limit: np.ndarray,
    names: tuple[str, ...],
    s: np.ndarray,
) -> None:
    """Refuse a plan that needs a joint faster than its limit: at a sample (J⁻¹ × twist) or
    between two samples (a jump: the configuration changed, a singularity was passed)."""
    dt = np.diff(np.concatenate([[0.0], times]))
    dq = np.diff(np.concatenate([q_start[None], q]), axis=0)
    need = np.maximum(np.abs(qd), np.abs(dq) / dt[:, None])
    refuse_first(
        need > limit * _SPEED_SLACK,
        "speed",
        lambda k, j: (
            f"{names[j]} would turn at {need[k, j]:.3g} rad/s, over its limit of "
            f"{limit[j]:.4g} rad/s, at {100 * s[k]:.0f}% of the line: lower the speed, or "
            f"the line passes too near a singularity"
        ),
    )
