"""TrajectoryTable: every running trajectory sampled at once, one numpy pass per tick.

Each active trajectory is a *slot*: its world, start tick, interpolation order and the point it
starts from (the world's target and velocity feed-forward when it was accepted). The points of
all slots live in flat arrays, one row per point, so a tick's work is a handful of array
operations over all slots whatever their number: find each slot's segment (it only moves
forward), build the segment's polynomial (linear, cubic or quintic, as ros2_controllers'
joint_trajectory_controller interpolates positions, +velocities, +accelerations) and evaluate it.

Time: the target in effect while tick k is stepped is the trajectory sampled at the *end* of
that tick, t = (k - start_tick + 1) × tick_dt, so the snapshot of tick k shows the actual
position at the instant whose desired position the servos were given. The last point is reached
at `end_tick` and held from then on with zero velocity feed-forward.

Not thread-safe: the manager calls it with the loop's command lock held.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from service.core.commands.trajectory.spec import JointTrajectorySpec

NJOINT = 7
_EPS = 1e-9  # slack on t_end / tick_dt so a duration of exactly n ticks ends at tick n


_PUBLIC_PER_SLOT = (
    "ids",
    "worlds",
    "start_tick",
    "end_tick",
    "path_tol",
    "goal_tol",
    "has_path",
    "has_goal",
    "goal_deadline",
    "duration",
)


class Sample(NamedTuple):
    """One tick's desired state of every slot (rows in slot order, all seven joints).

    positions [rad], velocities [rad/s] (the feed-forward), accelerations [rad/s²]: (S, 7);
    joints not in a slot's trajectory hold the start row's position with zero velocity (the
    manager writes only the driven joints: see `driven`).
    ended: the slot's last point is reached at or before this tick                    (S,)
    """

    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    ended: np.ndarray


def end_tick(start_tick: int, duration: float, tick_dt: float) -> int:
    """The first tick whose sample time reaches `duration` (the start tick itself for 0 s)."""
    return start_tick - 1 + max(1, math.ceil(duration / tick_dt - _EPS))


class TrajectoryTable:
    """The active trajectories of a batch: add, remove, sample, all vectorised over slots."""

    def __init__(self, tick_dt: float) -> None:
        self.tick_dt = float(tick_dt)
        self.ids = np.zeros(0, dtype=np.int64)  # the manager's trajectory id per slot
        self.worlds = np.zeros(0, dtype=np.int64)
        self.start_tick = np.zeros(0, dtype=np.int64)
        self.end_tick = np.zeros(0, dtype=np.int64)
        self._order = np.zeros(0, dtype=np.int64)
        self._mask = np.zeros((0, NJOINT), dtype=bool)
        self._start = np.zeros((0, 3, NJOINT))  # position, velocity, acceleration at t = 0
        self._first = np.zeros(0, dtype=np.int64)  # row of the slot's first point
        self._npts = np.zeros(0, dtype=np.int64)
        self._seg = np.zeros(0, dtype=np.int64)  # current segment: 0 = start → point 0
        # The current segment's polynomial per slot, refitted only when the segment changes.
        self._coef = np.zeros((0, 6, NJOINT))
        self._ta = np.zeros(0)  # the segment's start [s after the trajectory's start]
        self._len = np.zeros(0)  # its length [s]
        self._coef_seg = np.zeros(0, dtype=np.int64)  # segment the coefficients are for
        # Tolerances per slot and joint (+inf: not checked), and the last tick the goal may be
        # met by (end tick + goal_time_tolerance).
        self.path_tol = np.zeros((0, 2, NJOINT))  # position, velocity
        self.goal_tol = np.zeros((0, 2, NJOINT))
        self.has_path = np.zeros(0, dtype=bool)
        self.has_goal = np.zeros(0, dtype=bool)
        self.goal_deadline = np.zeros(0, dtype=np.int64)
        self.duration = np.zeros(0)  # time_from_start of the last point [s]
        # Flat point rows of every slot: time [s], and position/velocity/acceleration (7 wide).
        self._t = np.zeros(0)
        self._pva = np.zeros((0, 3, NJOINT))

    def __len__(self) -> int:
        return int(self.worlds.size)

    def add(
        self,
        traj_ids: np.ndarray,
        worlds: np.ndarray,
        spec: JointTrajectorySpec,
        start_tick: int,
        start_pos: np.ndarray,
        start_vel: np.ndarray,
    ) -> int:
        """Add one slot per world, all following `spec` from `start_tick`; returns the end tick.

        traj_ids, worlds: (k,); start_pos, start_vel: (k, 7), each world's target and velocity
        feed-forward now. One concatenation per table array whatever k is. The caller removes
        any slot of the same worlds first.
        """
        k, n, j = len(worlds), len(spec.times), spec.joints
        mask = np.zeros((k, NJOINT), dtype=bool)
        mask[:, j] = True
        rows = np.zeros((k, n, 3, NJOINT))
        rows[:, :, 0, :] = start_pos[:, None, :]  # joints outside the trajectory hold
        rows[:, :, 0, j] = spec.positions
        if spec.velocities is not None:
            rows[:, :, 1, j] = spec.velocities
        if spec.accelerations is not None:
            rows[:, :, 2, j] = spec.accelerations
        start = np.zeros((k, 3, NJOINT))
        start[:, 0] = start_pos
        start[:, 1] = np.where(mask, start_vel, 0.0)
        end = end_tick(start_tick, spec.duration, self.tick_dt)
        tol = np.full((2, 2, NJOINT), np.inf)
        tol[0, 0, j], tol[0, 1, j] = spec.path_position, spec.path_velocity
        tol[1, 0, j], tol[1, 1, j] = spec.goal_position, spec.goal_velocity
        grace = math.ceil(spec.goal_time_tolerance / self.tick_dt - _EPS)
        each = np.ones(k, dtype=np.int64)
        self._first = np.concatenate([self._first, self._t.size + n * np.arange(k)])
        self._t = np.concatenate([self._t, np.tile(spec.times, k)])
        self._pva = np.concatenate([self._pva, rows.reshape(k * n, 3, NJOINT)])
        grow = {
            "path_tol": np.repeat(tol[None, 0], k, axis=0),
            "goal_tol": np.repeat(tol[None, 1], k, axis=0),
            "has_path": np.full(k, spec.has_path_tolerance),
            "has_goal": np.full(k, spec.has_goal_tolerance),
            "goal_deadline": (end + grace) * each,
            "duration": np.full(k, spec.duration),
            "ids": np.asarray(traj_ids, dtype=np.int64),
            "worlds": np.asarray(worlds, dtype=np.int64),
            "start_tick": start_tick * each,
            "end_tick": end * each,
            "_order": spec.order * each,
            "_mask": mask,
            "_start": start,
            "_npts": n * each,
            "_seg": 0 * each,
            "_coef": np.zeros((k, 6, NJOINT)),
            "_ta": np.zeros(k),
            "_len": np.zeros(k),
            "_coef_seg": -each,
        }
        for name, new in grow.items():
            setattr(self, name, np.concatenate([getattr(self, name), new]))
        return end

    def remove(self, slots: np.ndarray) -> None:
        """Drop slots (indices into the current slot order) and their point rows."""
        slots = np.asarray(slots, dtype=np.int64)
        if slots.size == 0:
            return
        keep = np.ones(len(self), dtype=bool)
        keep[slots] = False
        row_keep = np.repeat(keep, self._npts)
        new_npts = self._npts[keep]
        self._t = self._t[row_keep]
        self._pva = self._pva[row_keep]
        self._first = np.cumsum(new_npts) - new_npts
        self._npts = new_npts
        for name in _PUBLIC_PER_SLOT:
            setattr(self, name, getattr(self, name)[keep])
        for name in ("_order", "_mask", "_start", "_seg", "_coef", "_ta", "_len", "_coef_seg"):
            setattr(self, name, getattr(self, name)[keep])

    def start_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """Each slot's start target and velocity feed-forward (S, 7): what `add` was given."""
        return self._start[:, 0].copy(), self._start[:, 1].copy()

    def slots_of(self, worlds: np.ndarray) -> np.ndarray:
        """Slot indices of those of `worlds` that have an active trajectory."""
        return np.flatnonzero(np.isin(self.worlds, worlds))

    def slots_driving(self, worlds: np.ndarray, joints: np.ndarray) -> np.ndarray:
        """Slot indices of those of `worlds` whose trajectory drives one of `joints` (indices)."""
        slots = self.slots_of(worlds)
        return slots[self._mask[slots][:, joints].any(axis=1)]

    def driven(self) -> np.ndarray:
        """Which joints each slot's trajectory drives (S, 7) bool (a view: do not modify)."""
        return self._mask

    def elapsed(self, tick: int) -> np.ndarray:
        """Sample time of every slot at `tick` [s] (negative before its start)."""
        return (tick - self.start_tick + 1) * self.tick_dt

    def sample(self, tick: int) -> Sample:
        """Every slot's desired state for the tick being stepped (`tick` = its number)."""
        t = self.elapsed(tick)
        last = self._first + self._npts - 1
        # Advance each slot's segment past every point time already reached (only forward).
        while True:
            more = (self._first + self._seg < last) & (t > self._t[self._first + self._seg])
            if not more.any():
                break
            self._seg += more
        stale = np.flatnonzero(self._coef_seg != self._seg)
        if stale.size:  # a new segment (or slot): its polynomial, once
            self._fit(stale)
        tau = np.clip(t - self._ta, 0.0, self._len)[:, None]
        c = self._coef
        pos = c[:, 0] + tau * (
            c[:, 1] + tau * (c[:, 2] + tau * (c[:, 3] + tau * (c[:, 4] + tau * c[:, 5])))
        )
        vel = c[:, 1] + tau * (
            2 * c[:, 2] + tau * (3 * c[:, 3] + tau * (4 * c[:, 4] + tau * 5 * c[:, 5]))
        )
        acc = 2 * c[:, 2] + tau * (6 * c[:, 3] + tau * (12 * c[:, 4] + tau * 20 * c[:, 5]))
        # At and after the end: exactly the last point with zero velocity, so the hold is
        # bit-exact whatever the float path above gave. (Joints outside a slot's trajectory
        # have constant polynomials: their start target, exactly, and zero velocity.)
        ended = tick >= self.end_tick
        if ended.any():
            e = ended[:, None]
            pos = np.where(e, self._pva[last, 0], pos)
            vel = np.where(e, 0.0, vel)
            acc = np.where(e, 0.0, acc)
        return Sample(pos, vel, acc, ended)

    def _fit(self, slots: np.ndarray) -> None:
        """The current segment's polynomial of `slots`: coefficients, start time, length."""
        seg = self._seg[slots]
        b_row = self._first[slots] + seg
        a_row = np.maximum(b_row - 1, 0)
        first = seg == 0
        a = np.where(first[:, None, None], self._start[slots], self._pva[a_row])
        b = self._pva[b_row]
        ta = np.where(first, 0.0, self._t[a_row])
        length = self._t[b_row] - ta
        self._coef[slots] = _coefficients(a, b, length, self._order[slots])
        self._ta[slots] = ta
        self._len[slots] = length
        self._coef_seg[slots] = seg


def _coefficients(a: np.ndarray, b: np.ndarray, seg_t: np.ndarray, order: np.ndarray) -> np.ndarray:
    """(S, 6, 7) polynomial coefficients in local time of each slot's segment a → b.

    a, b: (S, 3, 7) position/velocity/acceleration at the segment's ends; seg_t: (S,) its length.
    linear: constant slope; cubic: Hermite on p, v; quintic: Hermite on p, v, a (the orders of
    ros2_controllers' joint_trajectory_controller). Lower orders leave the high ones zero.
    A zero-length segment (a first point at t = 0) is never current: t >= tick_dt > 0.
    """
    T = np.where(seg_t > 0, seg_t, 1.0)[:, None]
    pa, va, aa = a[:, 0], a[:, 1], a[:, 2]
    pb, vb, ab = b[:, 0], b[:, 1], b[:, 2]
    h = pb - pa
    o = order[:, None]
    c = np.zeros((len(T), 6, pa.shape[1]))
    c[:, 0] = pa
    c[:, 1] = np.where(o == 1, h / T, va)
    c[:, 2] = np.where(o == 3, (3 * h - (2 * va + vb) * T) / T**2, np.where(o == 5, aa / 2, 0.0))
    quintic3 = (20 * h - (8 * vb + 12 * va) * T - (3 * aa - ab) * T**2) / (2 * T**3)
    c[:, 3] = np.where(o == 3, (-2 * h + (va + vb) * T) / T**3, np.where(o == 5, quintic3, 0.0))
    c[:, 4] = np.where(
        o == 5, (-30 * h + (14 * vb + 16 * va) * T + (3 * aa - 2 * ab) * T**2) / (2 * T**4), 0.0
    )
    c[:, 5] = np.where(o == 5, (12 * h - 6 * (vb + va) * T + (ab - aa) * T**2) / (2 * T**5), 0.0)
    return c
