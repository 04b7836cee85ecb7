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

from service.core.trajectory.spec import JointTrajectorySpec

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
)


class Sample(NamedTuple):
    """One tick's desired state of every slot (rows in slot order, all seven joints).

    positions [rad], velocities [rad/s] (the feed-forward), accelerations [rad/s²]: (S, 7);
    joints not in a slot's trajectory hold the start row's position with zero velocity.
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
        # Tolerances per slot and joint (+inf: not checked), and the last tick the goal may be
        # met by (end tick + goal_time_tolerance).
        self.path_tol = np.zeros((0, 2, NJOINT))  # position, velocity
        self.goal_tol = np.zeros((0, 2, NJOINT))
        self.has_path = np.zeros(0, dtype=bool)
        self.has_goal = np.zeros(0, dtype=bool)
        self.goal_deadline = np.zeros(0, dtype=np.int64)
        # Flat point rows of every slot: time [s], and position/velocity/acceleration (7 wide).
        self._t = np.zeros(0)
        self._pva = np.zeros((0, 3, NJOINT))

    def __len__(self) -> int:
        return int(self.worlds.size)

    def add(
        self,
        traj_id: int,
        world: int,
        spec: JointTrajectorySpec,
        start_tick: int,
        start_pos: np.ndarray,
        start_vel: np.ndarray,
    ) -> int:
        """Add a slot; `start_pos`/`start_vel` (7,) are the world's target and feed-forward now.

        Returns the trajectory's end tick. The caller removes any slot of the same world first.
        """
        j = spec.joints
        rows = np.zeros((len(spec.times), 3, NJOINT))
        rows[:, 0, :] = start_pos  # joints outside the trajectory hold their target
        rows[:, 0, j] = spec.positions
        if spec.velocities is not None:
            rows[:, 1, j] = spec.velocities
        if spec.accelerations is not None:
            rows[:, 2, j] = spec.accelerations
        start = np.zeros((1, 3, NJOINT))
        start[0, 0] = start_pos
        mask = np.zeros((1, NJOINT), dtype=bool)
        mask[0, j] = True
        start[0, 1] = np.where(mask[0], start_vel, 0.0)
        end = end_tick(start_tick, spec.duration, self.tick_dt)
        tol = np.full((2, 2, NJOINT), np.inf)
        tol[0, 0, j], tol[0, 1, j] = spec.path_position, spec.path_velocity
        tol[1, 0, j], tol[1, 1, j] = spec.goal_position, spec.goal_velocity
        self.path_tol = np.concatenate([self.path_tol, tol[:1]])
        self.goal_tol = np.concatenate([self.goal_tol, tol[1:]])
        self.has_path = np.append(self.has_path, spec.has_path_tolerance)
        self.has_goal = np.append(self.has_goal, spec.has_goal_tolerance)
        grace = math.ceil(spec.goal_time_tolerance / self.tick_dt - _EPS)
        self.goal_deadline = np.append(self.goal_deadline, end + grace)
        self._first = np.append(self._first, self._t.size)
        self._t = np.append(self._t, spec.times)
        self._pva = np.concatenate([self._pva, rows])
        self.ids = np.append(self.ids, traj_id)
        self.worlds = np.append(self.worlds, world)
        self.start_tick = np.append(self.start_tick, start_tick)
        self.end_tick = np.append(self.end_tick, end)
        self._order = np.append(self._order, spec.order)
        self._mask = np.concatenate([self._mask, mask])
        self._start = np.concatenate([self._start, start])
        self._npts = np.append(self._npts, len(spec.times))
        self._seg = np.append(self._seg, 0)
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
        for name in ("_order", "_mask", "_start", "_seg"):
            setattr(self, name, getattr(self, name)[keep])

    def slots_of(self, worlds: np.ndarray) -> np.ndarray:
        """Slot indices of those of `worlds` that have an active trajectory."""
        return np.flatnonzero(np.isin(self.worlds, worlds))

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
        b_row = self._first + self._seg
        a_row = b_row - 1
        first = self._seg == 0
        a = np.where(first[:, None, None], self._start, self._pva[np.maximum(a_row, 0)])
        b = self._pva[b_row]
        ta = np.where(first, 0.0, self._t[np.maximum(a_row, 0)])
        seg_t = self._t[b_row] - ta
        ended = tick >= self.end_tick
        tau = np.clip(t - ta, 0.0, seg_t)
        pos, vel, acc = _evaluate(a, b, seg_t, tau, self._order)
        # At and after the end: exactly the last point, with the last point's velocity (zero
        # after the end tick), so the hold is bit-exact whatever the float path above gave.
        pos = np.where(ended[:, None], b[:, 0], pos)
        vel = np.where(ended[:, None], 0.0, vel)
        acc = np.where(ended[:, None], 0.0, acc)
        hold = ~self._mask
        pos = np.where(hold, self._start[:, 0], pos)
        vel = np.where(hold, 0.0, vel)
        acc = np.where(hold, 0.0, acc)
        return Sample(pos, vel, acc, ended)


def _evaluate(
    a: np.ndarray, b: np.ndarray, seg_t: np.ndarray, tau: np.ndarray, order: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity, acceleration (S, 7) on each slot's segment a → b at local time tau.

    a, b: (S, 3, 7) position/velocity/acceleration at the segment's ends; seg_t, tau: (S,).
    The polynomial has up to six coefficients; lower orders leave the high ones zero.
    """
    T = np.where(seg_t > 0, seg_t, 1.0)[:, None]
    pa, va, aa = a[:, 0], a[:, 1], a[:, 2]
    pb, vb, ab = b[:, 0], b[:, 1], b[:, 2]
    h = pb - pa
    o = order[:, None]
    c = np.zeros((6, *pa.shape))
    c[0] = pa
    # linear: constant slope; cubic: Hermite on p, v; quintic: Hermite on p, v, a.
    c[1] = np.where(o == 1, h / T, va)
    c[2] = np.where(o == 3, (3 * h - (2 * va + vb) * T) / T**2, np.where(o == 5, aa / 2, 0.0))
    quintic3 = (20 * h - (8 * vb + 12 * va) * T - (3 * aa - ab) * T**2) / (2 * T**3)
    c[3] = np.where(o == 3, (-2 * h + (va + vb) * T) / T**3, np.where(o == 5, quintic3, 0.0))
    c[4] = np.where(
        o == 5, (-30 * h + (14 * vb + 16 * va) * T + (3 * aa - 2 * ab) * T**2) / (2 * T**4), 0.0
    )
    c[5] = np.where(o == 5, (12 * h - 6 * (vb + va) * T + (ab - aa) * T**2) / (2 * T**5), 0.0)
    s = tau[:, None]
    pos = c[0] + s * (c[1] + s * (c[2] + s * (c[3] + s * (c[4] + s * c[5]))))
    vel = c[1] + s * (2 * c[2] + s * (3 * c[3] + s * (4 * c[4] + s * 5 * c[5])))
    acc = 2 * c[2] + s * (6 * c[3] + s * (12 * c[4] + s * 20 * c[5]))
    # A zero-length segment (a first point at t = 0) is never current: t >= tick_dt > 0.
    return pos, vel, acc
