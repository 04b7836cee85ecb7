"""The host-side mirror every engine keeps: commanded targets, feed-forward, ticks and faults.

Whatever steps the worlds (a Warp device, native MuJoCo, worker processes, Ray actors), the
engine itself remembers in host memory what it was told and what it counted, so that `targets`
and `tick` answer without a device round trip, a lost shard can be rebuilt with its worlds'
targets, and a `BatchState` carries them. The rules are the same for every engine and live here
once: the door's order (`write`: resets, then state slices, then targets, as the commands
staged them, already clamped), a reset (asked for, or for a fault) puts a world back at home
with zero feed-forward, and faults are counted per world.

An engine mixes `HostMirror` in, calls `_init_mirror` in its constructor and uses the methods
below where it used to write the arrays itself; its device-side work stays its own.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import mujoco
import numpy as np

from service.core.sim.batch import ModelWrite, StateWrite, TickWrites
from service.core.sim.robot import LoadedRobot
from service.core.sim.types import MODEL_PREFIX, NJOINT, BatchState, RobotSpec

# Model fields that mj_setConst reads: after writing one, the constants derived from it
# (subtree masses, inverse weights at qpos0, actuator_acc0) are computed again, per world.
SETCONST_INPUTS = frozenset(mujoco.MjModel._setconst_inputs)


class HostMirror:
    """Host copies of targets (nworld, 7) [rad], velocity feed-forward (nworld, 7) [rad/s],
    ticks completed, ticks since each world's reset, faults per world, and the per-world
    values of every model field a command wrote (`_model`: field -> (nworld, ...) float64)."""

    spec: RobotSpec
    robot: LoadedRobot
    nworld: int
    _model: dict[str, np.ndarray]
    home_target: np.ndarray
    _targets: np.ndarray
    _velocity: np.ndarray
    _tick: int
    _world_ticks: np.ndarray
    _faults: np.ndarray
    tick_dt: float
    reset: Callable[[np.ndarray], None]  # the engine's own: state and targets back at home
    write_state: Callable[[StateWrite], None]  # the engine's own: a qpos/qvel slice now
    apply_targets: Callable[..., None]  # the engine's own: targets (and feed-forward) now
    push_model: Callable[[str, np.ndarray], None]  # the engine's own: `_model` rows into it

    def _init_mirror(self, nworld: int) -> None:
        """Every world at home, nothing counted yet (`spec` and `home_target` set before)."""
        self._tick = 0
        self._world_ticks = np.zeros(nworld, dtype=np.int64)
        self._faults = np.zeros(nworld, dtype=np.int64)
        self._targets = np.tile(self.home_target, (nworld, 1))
        self._velocity = np.zeros((nworld, NJOINT))
        self._model = {}

    @property
    def tick(self) -> int:
        """Control ticks completed since the batch was built."""
        return self._tick

    @property
    def targets(self) -> np.ndarray:
        """A copy of the targets in effect, (nworld, 7) [rad]."""
        return self._targets.copy()

    def write(self, writes: TickWrites) -> None:
        """The engines' one door (service.core.sim.batch): resets, then state, then targets."""
        self.write_before_targets(writes.resets, writes.model, writes.state)
        if writes.worlds.size:
            self.apply_targets(writes.worlds, writes.targets, writes.velocities)

    def write_before_targets(
        self, resets: np.ndarray, model: Sequence[ModelWrite], state: Sequence[StateWrite]
    ) -> None:
        """The door's order up to the targets: resets, then model values, then state slices
        (in the order staged). A shard applies its shipment with it too (engines/sharding.py),
        so that a sharded batch behaves like one."""
        self.reset(resets)
        if model:
            self.write_models(model)
        for write in state:
            self.write_state(write)

    def write_models(self, writes: Sequence[ModelWrite]) -> None:
        """Worlds' values of some model field entries: kept here, then each field pushed to
        the engine once (`push_model`, which makes it per world the first time), and the
        constants MuJoCo derives from them (mj_setConst) computed again when they depend on
        a field written (`derive_model`)."""
        touched: dict[str, set[int]] = {}
        for write in writes:
            rows = self._model.get(write.field)
            if rows is None:
                rows = self._model[write.field] = self.model_values(write.field)
            rows[write.world].flat[write.index] = write.values
            touched.setdefault(write.field, set()).add(write.world)
        for field, worlds in touched.items():
            self.push_model(field, np.array(sorted(worlds), dtype=np.int64))
        if SETCONST_INPUTS.intersection(touched):
            self.derive_model()

    def derive_model(self) -> None:
        """What mj_setConst derives, per world: each engine that steps worlds itself does it;
        engines of shards leave it to the shards, which get the model writes."""

    def model_values(self, field: str) -> np.ndarray:
        """Every world's values of MjModel field `field` (nworld, ...) float64, a copy."""
        rows = self._model.get(field)
        if rows is not None:
            return rows.copy()
        default = np.asarray(getattr(self.robot.mjm, field), dtype=np.float64)
        return np.repeat(default[None], self.nworld, axis=0)

    def _model_rows(self, field: str, worlds: np.ndarray) -> np.ndarray:
        """The values of `field` for `worlds` (k, ...) that the engine must hold now."""
        rows = self._model.get(field)
        return self.model_values(field)[worlds] if rows is None else rows[worlds]

    def _model_state(self) -> dict[str, np.ndarray]:
        """The per-world model fields, as `BatchState.physics` entries."""
        return {MODEL_PREFIX + f: rows.copy() for f, rows in self._model.items()}

    def _check_model_state(self, state: BatchState) -> dict[str, np.ndarray]:
        """The model fields of `state` (field -> rows), checked (ValueError naming the field)."""
        out = {}
        for key, rows in state.physics.items():
            if not key.startswith(MODEL_PREFIX):
                continue
            field = key[len(MODEL_PREFIX) :]
            default = getattr(self.robot.mjm, field, None)
            if not isinstance(default, np.ndarray):
                raise ValueError(f"{key!r} is not a model field of this scene")
            if rows.shape != (self.nworld, *default.shape) or not np.isfinite(rows).all():
                raise ValueError(
                    f"{key!r} has shape {rows.shape} or non-finite values, expected "
                    f"{(self.nworld, *default.shape)} finite"
                )
            out[field] = np.array(rows, dtype=np.float64)
        return out

    def _restore_model(self, fields: dict[str, np.ndarray]) -> None:
        """Take the checked model fields of a state: fields a command wrote before and the
        state lacks go back to the scene's values; every world of each is pushed."""
        gone = [f for f in self._model if f not in fields]
        self._model = {}
        for f in gone:
            self.push_model(f, np.arange(self.nworld))
        self._model = dict(fields)
        for f in fields:
            self.push_model(f, np.arange(self.nworld))
        if SETCONST_INPUTS.intersection([*gone, *fields]):
            self.derive_model()

    def host_columns(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sim_time [s], targets (k, 7), faults) of worlds `ids` from the mirror, copies."""
        return self._world_ticks[ids] * self.tick_dt, self._targets[ids], self._faults[ids]

    def _command(
        self, worlds: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None
    ) -> np.ndarray:
        """Record targets (as given: the command clamped them) and feed-forward (None: zero)
        for `worlds`; returns `worlds` as int64 ids for the engine's own write."""
        worlds = np.asarray(worlds, dtype=np.int64)
        self._targets[worlds] = targets
        self._velocity[worlds] = 0.0 if velocities is None else velocities
        return worlds

    def _home(self, worlds: np.ndarray) -> None:
        """`worlds` are back at home: home targets, no feed-forward, their time starts again."""
        self._targets[worlds] = self.home_target
        self._velocity[worlds] = 0.0
        self._world_ticks[worlds] = 0

    def _advance(self, ticks: int = 1) -> None:
        """`ticks` more control ticks completed, by every world."""
        self._tick += ticks
        self._world_ticks += ticks

    def _step_ticks(
        self, ticks: int, one_tick: Callable[[], np.ndarray], log: logging.Logger, what: str
    ) -> np.ndarray:
        """Run `one_tick` (which returns the worlds it broke) `ticks` times, counting ticks;
        broken worlds are counted, logged (`what` went wrong), reset to home and returned."""
        faulted: list[np.ndarray] = []
        for _ in range(ticks):
            bad = one_tick()
            self._advance()
            if bad.size:
                self._count_faults(bad)
                log.warning("worlds %s %s; reset to home", bad, what)
                self.reset(bad)
                faulted.append(bad)
        return np.concatenate(faulted) if faulted else np.zeros(0, dtype=np.int64)

    def _count_faults(self, worlds: np.ndarray) -> None:
        """`worlds` were reset for a fault (a world may be listed more than once); the engine
        resets them (and so calls `_home`) itself."""
        np.add.at(self._faults, worlds, 1)

    def _mirror_state(self, physics: dict[str, np.ndarray]) -> BatchState:
        """A `BatchState` of this mirror (copies) and the engine's `physics` arrays."""
        return BatchState(
            tick=self._tick,
            world_ticks=self._world_ticks.copy(),
            faults=self._faults.copy(),
            targets=self._targets.copy(),
            physics={**physics, **self._model_state()},
        )

    def _restore_mirror(
        self, state: BatchState, model: dict[str, np.ndarray] | None = None
    ) -> None:
        """Take the counters and targets of `state` (already checked); ctrl came with its
        physics, so the feed-forward starts at zero until the next command. `model`: the
        checked model fields, when the engine's parts took them already (shards)."""
        if model is not None:
            self._model = model
        self._tick = int(state.tick)
        self._world_ticks = np.array(state.world_ticks, dtype=np.int64)
        self._faults = np.array(state.faults, dtype=np.int64)
        self._targets = np.array(state.targets, dtype=np.float64)
        self._velocity = np.zeros_like(self._targets)
