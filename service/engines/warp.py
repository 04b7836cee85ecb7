"""WorldBatch: N independent UR10e worlds stepped together by MuJoCo Warp on one device.

The unit of work is a control tick: a fixed number of physics substeps followed by a gather of
the commanded joints' state into one compact array. The tick is recorded once as a graph
(``wp.ScopedCapture``: a CUDA graph on GPUs, an API capture replayed in C++ on the CPU) and
replayed every tick, because launching ~150 kernels per substep from Python costs ~6 ms on the CPU
whatever the batch size. Nothing in here is thread-safe: one thread (the loop) owns a WorldBatch.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Sequence
from pathlib import Path

import mujoco
import mujoco_warp as mjw
import numpy as np
import warp as wp

from mjcf import SCENE_XML
from service.core.sim.batch import Batch, ModelWrite, Renderable, Restorable, StateWrite
from service.core.sim.physics import (
    DEFAULT_PHYSICS_DT,
    configure,
    feedforward_gain,
    tick_timing,
    warp_solver,
)
from service.core.sim.robot import LoadedRobot, load_robot
from service.core.sim.types import PHYSICS_FIELDS, BatchState
from service.engines import warp_frames as frames
from service.engines import warp_newton
from service.engines.cuda_streams import engine_streams
from service.engines.mirror import SETCONST_INPUTS, HostMirror
from service.engines.warp_kernels import gather_bodies, gather_state
from service.engines.warp_model import (
    DERIVED,
    batched,
    host_layout,
    writable_fields,
    write_rows,
)
from service.engines.warp_reads import DeviceReads
from service.engines.warp_snapshot import NCOL

log = logging.getLogger("armfleet.engine")

# Warp logs a banner and one line per compiled module at INFO; the service keeps warnings only,
# `armfleet setup` (ARMFLEET_WARP_LOG=info) shows them as compile progress.
_VERBOSE_WARP = os.environ.get("ARMFLEET_WARP_LOG") == "info"
wp.config.log_level = wp.LOG_INFO if _VERBOSE_WARP else wp.LOG_WARNING

# Newton's solve on the CPU stops worlds whose warm start has converged (warp_newton.py: why).
warp_newton.install()

# Overflows that mean contacts or constraints were dropped: the world's physics is no longer
# trustworthy. (Solver iteration limits are not faults: the solution is just less converged.)
CAPACITY_OVERFLOWS = int(
    mjw.OverflowType.NEFC
    | mjw.OverflowType.NJMAX_NNZ
    | mjw.OverflowType.BROADPHASE
    | mjw.OverflowType.NARROWPHASE
    | mjw.OverflowType.CCD
)

# Per-world contact and constraint capacity. Measured on the grasp (pads on the cube, cube on
# the table, arm near the table): see tests/test_engine.py::test_grasp_never_overflows_capacity.
NCONMAX = 32
NJMAX = 128


class WorldBatch(HostMirror, DeviceReads, Batch, Restorable, Renderable):
    """N worlds of one model on one Warp device, advanced in captured control ticks.

    Targets live in a float64 host mirror (what was commanded, reported as `target`) and are
    written to the device in one array write per change, so commands for any subset of worlds
    cost the same. A world whose state goes non-finite or
    whose contact/constraint capacity overflows is reset to `home` after the tick that broke it
    and counted in `faults`; the other worlds are not touched.
    """

    def __init__(
        self,
        nworld: int,
        device: str = "cpu",
        control_hz: float = 60.0,
        physics_dt: float = DEFAULT_PHYSICS_DT,
        model_path: Path | str = SCENE_XML,
        capture: bool = True,
        nconmax: int = NCONMAX,
        njmax: int = NJMAX,
        robot: LoadedRobot | None = None,
        solver: mujoco.mjtSolver | None = None,
    ) -> None:
        """`solver`: the constraint solver; None is the engine's on this device
        (physics.warp_solver). Another one is for measuring them (bench section 24)."""
        if nworld < 1:
            raise ValueError(f"nworld must be >= 1, got {nworld}")
        self.robot = robot or load_robot(model_path)
        self.spec = self.robot.spec
        self.nworld = nworld
        self.shards = 1
        self.control_hz = float(control_hz)
        self.tick_dt = 1.0 / self.control_hz
        own = self.robot.own  # a cell that keeps its own timestep is stepped at it
        step = physics_dt if own is None else own.step(physics_dt)
        self.substeps, self.physics_dt = tick_timing(self.control_hz, step)
        self.device = wp.get_device(device)
        self.device_name = str(self.device)
        self.device_turns = engine_streams(self.device)  # ticks go first (cuda_streams.py)

        mjm = self.robot.mjm
        if solver is None:
            solver = warp_solver(self.device.is_cuda)  # physics.py: why
        configure(mjm, self.physics_dt, solver)
        home = mujoco.MjData(mjm)
        mujoco.mj_resetDataKeyframe(mjm, home, self.robot.home_key)
        mujoco.mj_forward(mjm, home)
        self.home_target = np.array(mjm.key_ctrl[self.robot.home_key], dtype=np.float64)

        self._init_mirror(nworld)
        self._ff_gain = feedforward_gain(mjm, self.robot.actuator_ids)
        self._graph = None
        self.capture_error: str | None = None

        t0 = time.perf_counter()
        with wp.ScopedDevice(self.device):
            self._m = mjw.put_model(mjm)
            if self.device.is_cpu:
                # A capture costs seconds on a CPU, on the sim thread, and every request that
                # needs a tick boundary (a snapshot, a recording's start, a read) waits behind
                # it: so every field a parameter may write is per world from the start, and no
                # write captures again (its cost in ticks: bench section `cells`, ~1%).
                for field in writable_fields(mjm, self.robot.spec.names):
                    batched(self._m, field, nworld, self.device)
            self._d = mjw.put_data(mjm, home, nworld=nworld, nconmax=nconmax, njmax=njmax)
            self._qpos_adr = wp.array(self.robot.qpos_adr, dtype=int)
            self._dof_adr = wp.array(self.robot.dof_adr, dtype=int)
            self._state = wp.zeros((nworld, NCOL), dtype=float)
            self._bodies = wp.zeros((nworld, mjm.nbody, 7), dtype=float)
            self._fault = wp.zeros(nworld, dtype=int)
            self._nfault = wp.zeros(1, dtype=int)
            # Device mirrors of the targets (ctrl also holds a velocity feed-forward), the world
            # tick counters and the fault counts, for packed frames.
            self._targets_dev = wp.zeros((nworld, 7), dtype=float)
            self._wticks = wp.zeros(nworld, dtype=wp.int64)
            self._faults_dev = wp.zeros(nworld, dtype=wp.int32)
            self._packer = frames.DevicePacker(self.device, self.tick_dt)
            self._pinned = frames.PinnedPool(self.device_turns)
            self._beside = frames.BesideCopy(self.device, self._pinned)
            self.copies_beside = self.device.is_cuda  # SnapshotsBeside: where it gains
            # One uncaptured tick compiles (or loads from cache) every kernel the tick uses;
            # capture needs them loaded. Then every world goes back to home.
            self._run_tick_ops()
            self.reset(np.arange(nworld))
            self._gather()  # tick 0's snapshot is exactly home
            self.compile_s = time.perf_counter() - t0
            self.capture_s = 0.0  # build's capture, and every one since (`_capture`)
            if capture:
                self._capture()

    # -- stepping ---------------------------------------------------------------------------

    def _run_tick_ops(self) -> None:
        """The work of one tick: substeps, then gather + fault check."""
        for _ in range(self.substeps):
            mjw.step(self._m, self._d)
        wp.launch(frames.count_tick, dim=self.nworld, inputs=[self._wticks])
        self._gather()

    def _gather(self) -> None:
        # Site poses from the last step are from before its integration; refresh them so the
        # flange pose belongs to the same instant as qpos.
        mjw.kinematics(self._m, self._d)
        self._nfault.zero_()
        d = self._d
        wp.launch(
            gather_state,
            dim=self.nworld,
            inputs=[
                d.qpos,
                d.qvel,
                d.qfrc_actuator,
                d.site_xpos,
                d.site_xmat,
                d.overflow,
                self._qpos_adr,
                self._dof_adr,
                self.robot.flange_site,
                CAPACITY_OVERFLOWS,
            ],
            outputs=[self._state, self._fault, self._nfault],
        )
        # One more launch per tick (~nbody x 7 floats per world) so viewers get every body.
        wp.launch(
            gather_bodies,
            dim=(self.nworld, self._bodies.shape[1]),
            inputs=[d.xpos, d.xquat],
            outputs=[self._bodies],
        )

    def _capture(self) -> None:
        t0 = time.perf_counter()
        try:
            with wp.ScopedCapture(device=self.device) as cap:
                self._run_tick_ops()
            self._graph = cap.graph
        except Exception as exc:  # capture support differs by device and driver
            self._graph = None
            self.capture_error = f"{type(exc).__name__}: {exc}"
            log.warning(
                "graph capture failed on %s (%s); stepping without capture (~6 ms/tick more)",
                self.device_name,
                self.capture_error,
            )
        finally:
            self.capture_s += time.perf_counter() - t0

    @property
    def captured(self) -> bool:
        return self._graph is not None

    def step(self, ticks: int = 1) -> np.ndarray:
        """Advance every world by `ticks` control ticks; returns the worlds reset for faults."""
        with wp.ScopedDevice(self.device):
            return self._step_ticks(ticks, self._one_tick, log, "hit NaN or capacity overflow")

    def _one_tick(self) -> np.ndarray:
        """One control tick (the captured graph, else the kernels one by one): worlds it broke."""
        if self._graph is not None:
            wp.capture_launch(self._graph)
        else:
            self._run_tick_ops()
        if self._read(self._nfault)[0]:
            return np.flatnonzero(self._read(self._fault))
        return np.zeros(0, dtype=np.int64)

    # -- commands ---------------------------------------------------------------------------

    def apply_targets(
        self, worlds: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None = None
    ) -> None:
        """Position targets for `worlds` (k,) ← `targets` (k, 7), in one device write, with a
        velocity feed-forward (k, 7) [rad/s] (None: zero) folded into ctrl (see physics)."""
        self._command(worlds, targets, velocities)
        self._push_targets()

    def _push_targets(self) -> None:
        ctrl = self._targets
        if self._velocity.any():  # else exactly the targets, as before feed-forward existed
            ctrl = self._targets + self._ff_gain * self._velocity
        if self.device.is_cpu:
            self._d.ctrl.numpy()[:] = ctrl  # a view of the same memory
        else:
            self._d.ctrl.assign(ctrl.astype(np.float32))
        self._mirror_targets()

    def _mirror_targets(self) -> None:
        if self.device.is_cpu:
            self._targets_dev.numpy()[:] = self._targets
        else:
            self._targets_dev.assign(self._targets.astype(np.float32))

    def reset(self, worlds: np.ndarray) -> None:
        """Reset `worlds` to `home`, state and targets; every other world stays bit-identical."""
        worlds = np.asarray(worlds, dtype=np.int64)
        if worlds.size == 0:
            return
        key = np.full(self.nworld, -1, dtype=np.int32)
        key[worlds] = self.robot.home_key
        with wp.ScopedDevice(self.device):
            key = wp.array(key, dtype=int)
            mjw.reset_data_keyframe(self._m, self._d, key)
            wp.launch(frames.zero_reset_ticks, dim=self.nworld, inputs=[key, self._wticks])
        self._home(worlds)
        self._mirror_targets()  # and the fault counts: a fault is counted just before its reset
        self._faults_dev.assign(self._faults.astype(np.int32))

    # -- reading ----------------------------------------------------------------------------

    # snapshot, snapshot_arrays, snapshot_beside and pack_rows: warp_reads.DeviceReads

    # -- state -----------------------------------------------------------------------------

    def physics_shapes(self) -> dict[str, tuple[int, ...]]:
        """Per-world shape of each physics field of `BatchState` for this model."""
        return {f: host_layout(getattr(self._d, f))[0][1:] for f in PHYSICS_FIELDS}

    def get_state(self) -> BatchState:
        """Every world's full state at the last tick boundary (host copies), see `BatchState`."""
        physics = {f: np.array(getattr(self._d, f).numpy(), copy=True) for f in PHYSICS_FIELDS}
        return self._mirror_state(physics)

    def set_state(self, state: BatchState) -> None:
        """Continue from `state` (same model and nworld): checked fully before anything changes.

        Raises ValueError naming the first mismatch; the batch is then untouched.
        """
        state.check_compatible(self.nworld, self.physics_shapes())
        model = self._check_model_state(state)
        with wp.ScopedDevice(self.device):
            self._restore_model(model)
            for f in PHYSICS_FIELDS:
                arr = state.physics[f]
                if arr.size:
                    dst = getattr(self._d, f)
                    dst.assign(arr.astype(host_layout(dst)[1], copy=False))
            # Overflow flags are sticky until a reset; at a tick boundary no world has a
            # capacity overflow (it would have been reset), so the restored batch starts clean.
            self._d.overflow.zero_()
            self._restore_mirror(state)
            self._wticks.assign(self._world_ticks)
            self._faults_dev.assign(self._faults.astype(np.int32))
            self._mirror_targets()
            self._gather()  # the snapshot shows the restored state at once

    # -- test and diagnostics hooks ---------------------------------------------------------

    def qpos(self) -> np.ndarray:
        """Full qpos of every world (nworld, nq), a host copy; for tests and diagnostics."""
        return np.array(self._d.qpos.numpy(), copy=True)

    def qvel(self) -> np.ndarray:
        return np.array(self._d.qvel.numpy(), copy=True)

    def render_state(self, worlds: np.ndarray) -> np.ndarray:
        """Renderable: the asked rows of this batch's own qpos (a copy of k rows)."""
        return self._read(self._d.qpos)[np.asarray(worlds, dtype=np.int64)]

    def _read(self, arr: wp.array) -> np.ndarray:
        """`arr` on the host, waiting for this engine's stream only (see PinnedPool.copy_out);
        a view of a buffer reused once no view of it is left (CPU: of the array itself)."""
        return self._pinned.copy_out((arr,), self.device)[0] if self.device.is_cuda else arr.numpy()

    def write_qpos(self, world: int, qpos: np.ndarray) -> None:
        """Overwrite one world's qpos (used to inject faults on purpose in tests)."""
        (full := self._d.qpos.numpy().copy())[world] = qpos
        self._d.qpos.assign(full)

    def write_state(self, write: StateWrite) -> None:
        """A qpos/qvel slice of one world (commands that move bodies are rare next to ticks)."""
        array = self._d.qpos if write.field == "qpos" else self._d.qvel
        row = array.numpy()[write.world : write.world + 1].copy()
        row[0, write.index] = write.values
        write_rows(array, np.array([write.world]), row, self.device.is_cpu)

    def write_models(self, writes: Sequence[ModelWrite]) -> None:
        """As HostMirror's, but the fields it makes per world (and what set_const derives from
        them) are made so first, and the tick captured again once for all of them, not once
        per field (a payload writes four)."""
        fields = {w.field for w in writes}
        if SETCONST_INPUTS.intersection(fields):
            fields.update(DERIVED)
        with wp.ScopedDevice(self.device):
            fresh = [batched(self._m, f, self.nworld, self.device) for f in sorted(fields)]
            if any(fresh) and self._graph is not None:
                self._capture()
        super().write_models(writes)

    def push_model(self, field: str, worlds: np.ndarray) -> None:
        """Per-world values of a Model field for `worlds` (see warp_model); the first write to
        a field makes it batched and captures the tick again (the graph holds the old array)."""
        with wp.ScopedDevice(self.device):
            if batched(self._m, field, self.nworld, self.device) and self._graph is not None:
                self._capture()
            rows = self._model_rows(field, worlds)
            write_rows(getattr(self._m, field), worlds, rows, self.device.is_cpu)

    def derive_model(self) -> None:
        """mjw.set_const: what mj_setConst derives (subtree masses, inverse weights at qpos0,
        actuator_acc0), per world; those outputs are made batched first, or every world would
        write the one shared row."""
        with wp.ScopedDevice(self.device):
            fresh = [batched(self._m, f, self.nworld, self.device) for f in DERIVED]
            if any(fresh) and self._graph is not None:
                self._capture()
            mjw.set_const(self._m, self._d)

    def batched_fields(self) -> list[str]:
        """The Model fields that hold one row per world (bench and tests)."""
        return [f for f in self._model if getattr(self._m, f).shape[0] == self.nworld]

    def close(self) -> None:
        """Nothing to release (device memory goes with the object); ShardedBatch stops workers."""

    def capacity_usage(self) -> tuple[int, int]:
        """(contacts in all worlds together, largest constraint count of any world) right now."""
        return int(self._d.nacon.numpy()[0]), int(self._d.nefc.numpy().max())
