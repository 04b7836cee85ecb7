"""NativeBatch: N worlds stepped by MuJoCo's C library on every core (``--engine mujoco``).

Warp's CPU backend runs its kernels on one core without SIMD, so on a CPU-only machine native
MuJoCo is ~3x faster per world-step. ``mujoco.batch.Batch`` (MuJoCo 4) keeps every world as
one row of integration state (qpos, qvel, warm start, ctrl, ...) and steps the rows on a C
thread pool with the GIL released; results are bit-identical to stepping one MjData per world,
at any thread count. It beats ``mujoco.rollout`` for a per-tick loop because nothing is tiled
or copied per call beyond the fields we bind (measured: bench/, section throughput).

Semantics match ``service.engines.warp.WorldBatch`` (the Batch protocol): targets are a float64 host
mirror written straight into the rows' ctrl; a world whose state goes non-finite, whose |qvel|
passes 1e4, or for which MuJoCo raises or warns (bad qpos/qvel/qacc, contact or constraint
buffer full: MuJoCo then resets the world to qpos0 itself) is reset to ``home`` after the tick
and counted in ``faults``; the other worlds are not touched. Effort is the actuator force of the
last substep (as with mj_step); the flange pose is computed at the state the snapshot reports.
Not thread-safe: one thread (the loop) owns a NativeBatch.
"""

from __future__ import annotations

import copy
import logging
import time
from pathlib import Path

import mujoco
import numpy as np
from mujoco import batch as mjbatch

from mjcf import SCENE_XML
from service.core.process.engine_priority import threads_started_by
from service.core.sim.batch import Batch, Renderable, Restorable, StateWrite
from service.core.sim.packed_rows import PackedRows
from service.core.sim.physics import (
    DEFAULT_PHYSICS_DT,
    ENGINE_SOLVER,
    configure,
    feedforward_gain,
    tick_timing,
)
from service.core.sim.robot import LoadedRobot, load_robot
from service.core.sim.types import PHYSICS_FIELDS, BatchState, Poses, Snapshot
from service.engines.cores import usable_cores
from service.engines.mirror import HostMirror
from service.engines.native_kinematics import PoseReader

log = logging.getLogger("armfleet.native")

# A joint spinning faster than this [rad/s or m/s] has blown up even if it is still finite
# (the same limit as the warp engine's).
DIVERGED_QVEL = 1.0e4


# Below this many worlds per thread a tick is too short for the pool: handing work to a second
# thread (and waiting for it when the machine is busy) costs more than the thread brings.
MIN_WORLDS_PER_THREAD = 32


def auto_threads(nworld: int) -> int:
    """Threads to step `nworld` worlds on: one per usable core once the batch is big enough."""
    return max(1, min(usable_cores(), nworld // MIN_WORLDS_PER_THREAD))


def _adjacent(a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """One read-only view of row fields `a` then `b` when `b` starts where `a` ends in every
    row (same row stride), else None."""
    start = a.__array_interface__["data"][0]
    follows = b.__array_interface__["data"][0] == start + a.shape[1] * a.itemsize
    if not follows or a.strides != b.strides or a.dtype != b.dtype or a.strides[1] != a.itemsize:
        return None
    shape = (a.shape[0], a.shape[1] + b.shape[1])
    return np.lib.stride_tricks.as_strided(a, shape=shape, strides=a.strides, writeable=False)


def _with_sleep(mjm: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of `mjm` with MuJoCo's sleeping on: a tree at rest long enough skips collision,
    constraints and integration until something awake touches it or its state is written."""
    model = copy.copy(mjm)
    model.opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    return model


class NativeBatch(HostMirror, Batch, Restorable, Renderable):
    """N worlds of one model in native MuJoCo, advanced a control tick at a time on a pool."""

    shards = 1  # one batch; the cores are used by threads, not processes
    captured = False  # no graph: there is nothing to capture on this engine
    capture_error: str | None = None
    capture_s = 0.0

    def __init__(
        self,
        nworld: int,
        control_hz: float = 60.0,
        physics_dt: float = DEFAULT_PHYSICS_DT,
        nthread: int = 0,
        model_path: Path | str = SCENE_XML,
        robot: LoadedRobot | None = None,
        device: str = "cpu",
    ) -> None:
        if nworld < 1:
            raise ValueError(f"nworld must be >= 1, got {nworld}")
        if not device.startswith("cpu"):
            raise ValueError(f"the mujoco engine runs on the CPU only, not on {device!r}")
        t0 = time.perf_counter()
        self.robot = robot or load_robot(model_path)
        self.spec = self.robot.spec
        self.nworld = nworld
        self.control_hz = float(control_hz)
        self.tick_dt = 1.0 / self.control_hz
        own = self.robot.own  # a cell that keeps its own timestep is stepped at it
        step = physics_dt if own is None else own.step(physics_dt)
        self.substeps, self.physics_dt = tick_timing(self.control_hz, step)
        self.nthread = max(1, min(nthread or auto_threads(nworld), nworld))
        self.device_name = f"cpu (native MuJoCo, {self.nthread} thread{'s' * (self.nthread > 1)})"

        mjm = self.robot.mjm
        configure(mjm, self.physics_dt, ENGINE_SOLVER["mujoco"])
        self.home_target = np.array(mjm.key_ctrl[self.robot.home_key], dtype=np.float64)
        self._key = self.robot.home_key
        self._dof = self.robot.dof_adr
        self._qpos_adr = self.robot.qpos_adr

        # The batch copies the model: options are set above, before it is built. A scene that
        # lets bodies at rest sleep sleeps here, with one MjData kept per world (persistent):
        # MuJoCo keeps who sleeps there, not in the rows; writing a row wakes its body.
        sleep = self.robot.sleep
        model = _with_sleep(mjm) if sleep else mjm
        # its pool's threads (nthread - 1 beside the caller's) step with the loop's thread
        self._b, self._pool = threads_started_by(
            lambda: mjbatch.Batch(model, nworld, nthread=self.nthread, persistent=sleep)
        )
        self._poses = PoseReader(mjm, nworld, self.nthread, self.robot.flange_site)
        self._qpos = self._b.bind("qpos")  # live views of the state rows
        self._qvel = self._b.bind("qvel")
        self._ctrl = self._b.bind("ctrl")
        self._qfrc_actuator = self._b.bind("qfrc_actuator")  # outputs, refreshed per call

        self._init_mirror(nworld)
        self._ff_gain = feedforward_gain(mjm, self.robot.actuator_ids)
        self._pv = _adjacent(self._qpos, self._qvel)  # qpos|qvel rows, read in one copy
        self._nq = self._qpos.shape[1]
        self._vel_cols = self._nq + self._dof  # the joints' qvel columns in those rows
        self._now: np.ndarray | None = None  # the rows as they are now, copied (`_rows_now`)
        self._effort: np.ndarray | None = None  # (nworld, 7) of the last step (`_effort_now`)
        self._warn_last = np.array(self._b.warning)  # every world's counters as last seen
        self._warn_seen = self._warn_last.tobytes()  # ... as bytes, for the quick test
        self.reset(np.arange(nworld))
        self.compile_s = time.perf_counter() - t0  # nothing compiles: this is the build time

    # -- stepping ---------------------------------------------------------------------------

    @staticmethod
    def _warnings(warning: np.ndarray) -> np.ndarray:
        """Per world, how many warnings MuJoCo has raised in it (all kinds together), from the
        batch's (nworld, kinds, 2) warning counters."""
        return warning[:, :, 1].sum(axis=1, dtype=np.int64)

    def _step_tick(self) -> np.ndarray:
        """One control tick for every world; returns the worlds that went bad in it."""
        raised = np.zeros(0, dtype=np.int64)
        try:
            self._b.step(nstep=self.substeps)
        except mjbatch.SimulationError as exc:  # those worlds kept their pre-call state
            raised = np.asarray(exc.ids, dtype=np.int64)
            log.warning("MuJoCo raised in worlds %s: %s", raised, exc)
        finally:  # the rows and the effort are this call's now (read when first needed)
            self._now, self._effort = None, None
        rows = self._rows_now()
        if raised.size == 0 and self._all_well(rows):
            return raised
        nq = self._nq
        bad = ~np.isfinite(rows[:, :nq]).all(axis=1)
        bad |= ~(np.abs(rows[:, nq:]) <= DIVERGED_QVEL).all(axis=1)  # NaN compares False: caught
        bad |= self._warnings(self._b.warning) != self._warnings(self._warn_last)
        bad[raised] = True
        self._saw_warnings()  # the bad worlds' resets update it again
        return np.flatnonzero(bad)

    def _all_well(self, rows: np.ndarray) -> bool:
        """True when no world can be bad: a sufficient test on whole arrays, cheaper than the
        per-world one that `_step_tick` runs when it fails.

        `rows` is the tick's contiguous copy of qpos|qvel (`_rows_now`), tested flat (numpy
        reduces short rows of a 2-D array slowly) by its extremes, without writing anything:
        every qpos and qvel within +-DIVERGED_QVEL (a NaN makes max and min NaN, which
        compares False) implies finite qpos and qvel in bounds; warning counters equal to
        those last seen imply no new warning.
        """
        if not (rows.max() <= DIVERGED_QVEL and rows.min() >= -DIVERGED_QVEL):
            return False
        return self._b.warning.tobytes() == self._warn_seen  # one copy and a memcmp

    def _saw_warnings(self) -> None:
        """Every world's warning counters as they are now are the ones seen."""
        self._warn_last[:] = self._b.warning
        self._warn_seen = self._warn_last.tobytes()

    def _rows_now(self) -> np.ndarray:
        """Every world's qpos|qvel row (nworld, nq + nv) as the state is now: one contiguous
        copy per state, read-only, which the fault check, frames and snapshots all read.

        The rows were just written by the pool's threads on other cores: reading them costs
        cache transfers, so they are read once, here, instead of by every reader. Whatever
        changes the state (a step, a reset, a write) drops it; a frame or snapshot that holds
        it keeps its own, since a later state gets a new array.
        """
        if self._now is None:
            if self._pv is not None:  # qpos and qvel adjacent in the row: one copy
                self._now = np.array(self._pv)
            else:
                self._now = np.concatenate((self._qpos, self._qvel), axis=1)
            self._now.flags.writeable = False
        return self._now

    def _effort_now(self) -> np.ndarray:
        """Every world's effort (nworld, 7): the actuator force of the last step's last substep
        (a reset world's: the reset's; a restored state's: the one it carried), read-only.
        Read from the step's outputs when first asked for (a frame, a snapshot, a save), not
        every tick: most ticks nobody asks. A reset refreshes only its worlds' outputs, so
        until then the other rows still hold the step's; once read, later resets patch it."""
        if self._effort is None:
            self._effort = np.take(self._qfrc_actuator, self._dof, axis=1)
            self._effort.flags.writeable = False
        return self._effort

    def step(self, ticks: int = 1) -> np.ndarray:
        """Advance every world by `ticks` control ticks; returns the worlds reset for faults."""
        return self._step_ticks(ticks, self._step_tick, log, "went non-finite or diverged")

    # -- commands ---------------------------------------------------------------------------

    def apply_targets(
        self, worlds: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None = None
    ) -> None:
        """Position targets for `worlds` (k,) <- `targets` (k, 7), written into their rows,
        with a velocity feed-forward (k, 7) [rad/s] (None: zero) folded in (see physics)."""
        worlds = self._command(worlds, targets, velocities)
        if velocities is None or not np.any(velocities):
            self._ctrl[worlds] = self._targets[worlds]
        else:
            self._ctrl[worlds] = self._targets[worlds] + self._ff_gain * velocities

    def reset(self, worlds: np.ndarray) -> None:
        """Reset `worlds` to `home`, state and targets; every other world stays bit-identical."""
        worlds = np.asarray(worlds, dtype=np.int64)
        if worlds.size == 0:
            return
        # mj_resetDataKeyframe + mj_forward per world: ctrl = home, outputs current.
        self._b.reset(worlds, keyframe=self._key)
        self._home(worlds)
        self._saw_warnings()  # only the reset worlds' counters can have moved
        self._now = None
        if self._effort is not None:  # read already (or restored): these worlds' are reset's
            effort = self._effort.copy()
            effort[worlds] = self._qfrc_actuator[worlds][:, self._dof]
            effort.flags.writeable = False
            self._effort = effort

    # -- reading ----------------------------------------------------------------------------

    def snapshot(self) -> Snapshot:
        """All worlds at the end of the last completed tick, copied.

        States are float32 as the warp engine's are: the same frames on the wire (a float64
        JSON number is ~twice as long, and serialising frames is what a CPU service spends
        most on besides physics); targets stay float64, as commanded. Poses (flange, bodies)
        are computed when first read, from a copy of this tick's qpos: most snapshots are
        never asked for them.
        """
        rows = self._rows_now()
        qpos = rows[:, : self._nq]  # a view of this state's copy, which nothing writes
        f32 = np.float32
        return Snapshot(
            tick=self._tick,
            sim_time=self._world_ticks * self.tick_dt,
            # New C-ordered arrays (the wire serialises rows of them; fancy indexing alone
            # may hand back a column-major array).
            position=np.ascontiguousarray(rows[:, self._qpos_adr], dtype=f32),
            velocity=np.ascontiguousarray(rows[:, self._vel_cols], dtype=f32),
            effort=self._effort_now().astype(f32, order="C"),
            target=self._targets.copy(),
            faults=self._faults.copy(),
            flange=Poses(compute=lambda: self._poses.flange_f32(qpos)),
            bodies=Poses(compute=lambda: self._poses.bodies_f32(qpos)),
        )

    def pack_rows(self, ids: np.ndarray) -> PackedRows:
        """The frame rows (service.wire.BINARY_COLUMNS) of worlds `ids` at the last tick, as
        `snapshot` reports them. Here (the sim thread, between ticks) only the host mirrors of
        those worlds are copied: the state's rows and effort are this state's own read-only
        copies (`_rows_now`, `_effort_now`), which no later tick writes. Picking the worlds'
        columns, the flange pose and the packing run in `PackedRows.wait`, on the frame thread,
        while the next tick steps: serial work here leaves a core idle."""
        rows, effort = self._rows_now(), self._effort_now()
        ticks, targets, faults = self._world_ticks[ids], self._targets[ids], self._faults[ids]
        nq, pos_cols, vel_cols, dt = self._nq, self._qpos_adr, self._vel_cols, self.tick_dt

        def build() -> np.ndarray:
            q = rows[ids]
            flange_pos, flange_quat = self._poses.flange(q[:, :nq])
            cols = (
                (ticks * dt)[:, None],
                q[:, pos_cols],
                q[:, vel_cols],
                effort[ids],
                targets,
                flange_pos,
                flange_quat,
                faults[:, None],
            )
            return np.concatenate(cols, axis=1, dtype="<f4")

        host = (ticks * dt, targets, faults)  # `host_columns` of the same copies
        return PackedRows(self._tick, ids, None, compute=build, host=host)

    # -- state ------------------------------------------------------------------------------

    def _state_field(self, name: str) -> np.ndarray:
        """A live row view of an integration-state field (qfrc_actuator: read-only output)."""
        return self._b.bind(name)

    def physics_shapes(self) -> dict[str, tuple[int, ...]]:
        return {f: tuple(self._state_field(f).shape[1:]) for f in PHYSICS_FIELDS}

    def get_state(self) -> BatchState:
        """Every world's full state (see `BatchState`); float64 rows, eq_active as bool."""
        physics = {f: np.array(self._state_field(f), copy=True) for f in PHYSICS_FIELDS}
        physics["eq_active"] = physics["eq_active"] != 0
        # The effort the snapshot reports is the last tick's (`_effort_now`): store it there.
        physics["qfrc_actuator"][:, self._dof] = self._effort_now()
        return self._mirror_state(physics)

    def set_state(self, state: BatchState) -> None:
        """Continue from `state`; checked fully first (ValueError, nothing changed)."""
        state.check_compatible(self.nworld, self.physics_shapes())
        model = self._check_model_state(state)
        self._restore_model(model)
        for f in PHYSICS_FIELDS:
            if f != "qfrc_actuator" and state.physics[f].size:
                self._state_field(f)[:] = state.physics[f]
        self._restore_mirror(state)
        self._now = None
        self._effort = np.array(state.physics["qfrc_actuator"][:, self._dof], dtype=np.float64)
        self._effort.flags.writeable = False  # until the next step, which makes its own
        self._saw_warnings()

    # -- test and diagnostics hooks ---------------------------------------------------------

    def qpos(self) -> np.ndarray:
        """Full qpos of every world (nworld, nq), a copy; for tests and diagnostics."""
        return self._qpos.copy()

    def render_state(self, worlds: np.ndarray) -> np.ndarray:
        """Renderable: the asked worlds' qpos rows, copied for the render batch."""
        return self._qpos[np.asarray(worlds, dtype=np.int64)].copy()

    def qvel(self) -> np.ndarray:
        return self._qvel.copy()

    def write_qpos(self, world: int, qpos: np.ndarray) -> None:
        """Overwrite one world's qpos (used to inject faults on purpose in tests)."""
        self._qpos[world] = qpos
        self._now = None

    def write_state(self, write: StateWrite) -> None:
        """A qpos/qvel slice of one world, into its row of the live state."""
        rows = self._qpos if write.field == "qpos" else self._qvel
        rows[write.world, write.index] = write.values
        self._now = None

    def push_model(self, field: str, worlds: np.ndarray) -> None:
        """Per-world values of an MjModel field (`mujoco.batch` expands it on first use)."""
        self._b.expand(field)[worlds] = self._model_rows(field, worlds)

    def derive_model(self) -> None:
        """mj_setConst per world, as after editing an MjModel's masses or armature by hand."""
        self._effort_now()  # read from the last step's outputs before another call may redo them
        self._b.set_const()

    def capacity_usage(self) -> tuple[int, int]:
        """(contacts in all worlds together, largest constraint count of any world) as of the
        last call; native MuJoCo grows its buffers, this is for comparison with the warp engine.
        The first call binds the fields and reads zeros."""
        ncon, nefc = self._b.bind("ncon"), self._b.bind("nefc")
        return int(ncon.sum()), int(nefc.max())

    def stepping_ids(self) -> tuple[int, ...]:
        """The pool's threads (the batch's SteppedBeside): they step beside the loop's thread."""
        return self._pool

    def close(self) -> None:
        """Nothing to release: the pool's threads go with the object."""
