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
from collections.abc import Callable

import numpy as np

from service.core.batch import StateWrite, TickWrites
from service.core.types import NJOINT, BatchState, RobotSpec


class HostMirror:
    """Host copies of targets (nworld, 7) [rad], velocity feed-forward (nworld, 7) [rad/s],
    ticks completed, ticks since each world's reset, and faults per world."""

    spec: RobotSpec
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

    def _init_mirror(self, nworld: int) -> None:
        """Every world at home, nothing counted yet (`spec` and `home_target` set before)."""
        self._tick = 0
        self._world_ticks = np.zeros(nworld, dtype=np.int64)
        self._faults = np.zeros(nworld, dtype=np.int64)
        self._targets = np.tile(self.home_target, (nworld, 1))
        self._velocity = np.zeros((nworld, NJOINT))

    @property
    def tick(self) -> int:
        """Control ticks completed since the batch was built."""
        return self._tick

    @property
    def targets(self) -> np.ndarray:
        """A copy of the targets in effect, (nworld, 7) [rad]."""
        return self._targets.copy()

    def write(self, writes: TickWrites) -> None:
        """The engines' one door (service.core.batch): resets, then state, then targets."""
        self.reset(writes.resets)
        for state in writes.state:
            self.write_state(state)
        if writes.worlds.size:
            self.apply_targets(writes.worlds, writes.targets, writes.velocities)

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
            physics=physics,
        )

    def _restore_mirror(self, state: BatchState) -> None:
        """Take the counters and targets of `state` (already checked); ctrl came with its
        physics, so the feed-forward starts at zero until the next command."""
        self._tick = int(state.tick)
        self._world_ticks = np.array(state.world_ticks, dtype=np.int64)
        self._faults = np.array(state.faults, dtype=np.int64)
        self._targets = np.array(state.targets, dtype=np.float64)
        self._velocity = np.zeros_like(self._targets)
