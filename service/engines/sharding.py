"""What every sharded engine shares: the world split, staged commands, the shard's step, joining.

ShardedBatch (worker processes on one machine) and RayBatch (Ray actors, one machine or many)
differ only in how they reach a shard. Both split N worlds into contiguous blocks, stage commands
per shard until the next step (a shard applies them just before it steps, so they cross the wire
once, with the step), and join the shards' snapshots back into one. That logic lives here, once,
so the two engines cannot drift apart in the lockstep semantics the tests pin down.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from service.core.sim.batch import ModelWrite, StateWrite
from service.core.sim.types import MODEL_PREFIX, BatchState, Poses, Snapshot
from service.engines.warp import WorldBatch

_EMPTY = np.zeros(0, dtype=np.int64)

# Snapshot fields that are per world and are joined shard after shard.
WORLD_FIELDS = (
    "sim_time",
    "position",
    "velocity",
    "effort",
    "flange_pos",
    "flange_quat",
    "body_pos",
    "body_quat",
)


class ShardPlan:
    """`nworld` worlds as `shards` contiguous blocks of near-equal size.

    starts: first global world id of each shard   (shards,)
    sizes: worlds in each shard                     (shards,)
    """

    def __init__(self, nworld: int, shards: int) -> None:
        if not 1 <= shards <= nworld:
            raise ValueError(f"shards must be in 1..{nworld}, got {shards}")
        bounds = np.linspace(0, nworld, shards + 1).astype(np.int64)
        self.nworld = nworld
        self.shards = shards
        self.starts = bounds[:-1]
        self.sizes = np.diff(bounds)

    def split(self, worlds: np.ndarray) -> list[np.ndarray]:
        """Global world ids → the local ids of each shard (one array per shard, maybe empty)."""
        worlds = np.asarray(worlds, dtype=np.int64)
        return [
            worlds[(worlds >= start) & (worlds < start + size)] - start
            for start, size in zip(self.starts, self.sizes, strict=True)
        ]

    def locate(self, world: int) -> tuple[int, int]:
        """(the shard holding global world `world`, its local id there)."""
        shard = int(np.searchsorted(self.starts, world, side="right")) - 1
        return shard, world - int(self.starts[shard])

    def worlds_of(self, shard: int) -> np.ndarray:
        """The global ids of one shard's worlds."""
        start = int(self.starts[shard])
        return np.arange(start, start + int(self.sizes[shard]), dtype=np.int64)


class Shipment(NamedTuple):
    """What one shard's next step carries (local ids): resets, then model values, then state
    slices, then the dirty worlds' command rows (`command_rows`), applied in that order
    (`apply`)."""

    resets: np.ndarray
    dirty: np.ndarray
    rows: np.ndarray
    state: tuple[StateWrite, ...] = ()
    model: tuple[ModelWrite, ...] = ()

    def apply(self, batch: WorldBatch) -> None:
        """A shard's side: the loop's order, so a shard behaves like one WorldBatch."""
        batch.write_before_targets(self.resets, self.model, self.state)
        apply_rows(batch, self.dirty, self.rows)


NOTHING = Shipment(_EMPTY, _EMPTY, np.zeros((0, 7)))


class StagedCommands:
    """Per shard, the resets, state slices and target changes waiting to travel with that
    shard's next step.

    Targets are not copied here: the caller keeps one target table and reads the dirty rows when
    the step is sent, so a world commanded twice in one tick sends its last target once.
    """

    def __init__(self, shards: int) -> None:
        self._resets: list[np.ndarray] = [_EMPTY] * shards
        self._dirty: list[np.ndarray] = [_EMPTY] * shards
        self._state: list[list[StateWrite]] = [[] for _ in range(shards)]
        self._model: list[list[ModelWrite]] = [[] for _ in range(shards)]

    def targets(self, shard: int, local_ids: np.ndarray) -> None:
        if local_ids.size:
            self._dirty[shard] = np.union1d(self._dirty[shard], local_ids)

    def reset(self, shard: int, local_ids: np.ndarray) -> None:
        """A reset overrides targets staged before it in the same tick (a reset sets home)."""
        if local_ids.size:
            self._resets[shard] = np.union1d(self._resets[shard], local_ids)
            self._dirty[shard] = np.setdiff1d(self._dirty[shard], local_ids)
            self._state[shard] = [w for w in self._state[shard] if w.world not in local_ids]

    def state(self, shard: int, write: StateWrite) -> None:
        """A state slice (its world a local id), applied after the shard's resets."""
        self._state[shard].append(write)

    def model(self, shard: int, write: ModelWrite) -> None:
        """Model values (their world a local id); a reset does not undo them."""
        self._model[shard].append(write)

    def targets_of(self, parts: Sequence[np.ndarray], first: int = 0) -> None:
        """`targets` for each shard's part of a command (`ShardPlan.split`), from shard `first`."""
        for shard, local_ids in enumerate(parts, start=first):
            self.targets(shard, local_ids)

    def resets_of(self, parts: Sequence[np.ndarray], first: int = 0) -> None:
        """`reset` for each shard's part of a reset (`ShardPlan.split`), from shard `first`."""
        for shard, local_ids in enumerate(parts, start=first):
            self.reset(shard, local_ids)

    def take(self, shard: int) -> tuple[np.ndarray, np.ndarray]:
        """(resets, dirty) local ids for the shard's next step; the shard's stage is emptied."""
        out = self._resets[shard], self._dirty[shard]
        self._resets[shard] = _EMPTY
        self._dirty[shard] = _EMPTY
        self._state[shard] = []
        self._model[shard] = []
        return out

    def ship(self, shard: int, targets: np.ndarray, velocity: np.ndarray, start: int) -> Shipment:
        """The shard's next step's `Shipment` (rows read from the caller's one target table,
        `start` its first global world); the shard's stage is emptied."""
        state, model = tuple(self._state[shard]), tuple(self._model[shard])
        resets, dirty = self.take(shard)
        rows = command_rows(targets, velocity, dirty + start)
        return Shipment(resets, dirty, rows, state, model)


def command_rows(targets: np.ndarray, velocity: np.ndarray, worlds: np.ndarray) -> np.ndarray:
    """The rows of `worlds` to send to a shard: targets (k, 7), with the velocity feed-forward
    appended, (k, 14), only when some of it is non-zero (so plain commands travel as before)."""
    vel = velocity[worlds]
    return np.concatenate([targets[worlds], vel], axis=1) if vel.any() else targets[worlds]


def apply_rows(batch: WorldBatch, dirty: np.ndarray, rows: np.ndarray) -> None:
    """A shard's side of `command_rows`: targets, and feed-forward when the rows carry it."""
    if dirty.size:
        if rows.shape[1] > 7:
            batch.apply_targets(dirty, rows[:, :7], rows[:, 7:])
        else:
            batch.apply_targets(dirty, rows)


def apply_and_step(batch: WorldBatch, shipment: Shipment, ticks: int) -> np.ndarray:
    """A shard's side of one step: what was staged (`Shipment.apply`), then the ticks.
    Returns the shard's faulted local ids."""
    shipment.apply(batch)
    return batch.step(ticks)


def join_snapshots(parts: Sequence[Snapshot], tick: int, targets: np.ndarray) -> Snapshot:
    """One Snapshot from the shards' snapshots, in shard order; `targets` is the caller's table."""
    joined = {f: np.concatenate([getattr(p, f) for p in parts]) for f in WORLD_FIELDS}
    flange = Poses(joined.pop("flange_pos"), joined.pop("flange_quat"))
    bodies = Poses(joined.pop("body_pos"), joined.pop("body_quat"))
    return Snapshot(
        tick=tick,
        target=targets.copy(),
        faults=np.concatenate([p.faults for p in parts]),
        flange=flange,
        bodies=bodies,
        **joined,
    )


def slice_state(state: BatchState, start: int, stop: int) -> BatchState:
    """Worlds start..stop of a state, as a state of its own (one shard's part)."""
    return BatchState(
        tick=state.tick,
        world_ticks=state.world_ticks[start:stop],
        faults=state.faults[start:stop],
        targets=state.targets[start:stop],
        physics={k: v[start:stop] for k, v in state.physics.items()},
    )


def join_states(
    parts: Sequence[BatchState],
    targets: np.ndarray,
    model: dict[str, np.ndarray] | None = None,
) -> BatchState:
    """One state from the shards' states, in shard order; `targets` and the per-world model
    fields (`MODEL_PREFIX` entries) are the caller's, which knows every world's."""
    physics = {
        k: np.concatenate([p.physics[k] for p in parts])
        for k in parts[0].physics
        if not k.startswith(MODEL_PREFIX)
    }
    return BatchState(
        tick=parts[0].tick,
        world_ticks=np.concatenate([p.world_ticks for p in parts]),
        faults=np.concatenate([p.faults for p in parts]),
        targets=targets.copy(),
        physics={**physics, **(model or {})},
    )


def stage_model(
    plan: ShardPlan,
    staged: StagedCommands,
    field: str,
    rows: np.ndarray,
    worlds: np.ndarray,
    local: WorldBatch | None = None,
) -> None:
    """Whole rows of model field `field` (k, ...) for global `worlds`: staged for the shard
    holding each, or written now into `local` (shard 0 in this process) when given."""
    flat = rows.reshape(len(worlds), -1)
    index = np.arange(flat.shape[1], dtype=np.int64)
    now: list[ModelWrite] = []
    for i, w in enumerate(worlds):
        shard, local_id = plan.locate(int(w))
        write = ModelWrite(field, local_id, index, flat[i])
        if shard == 0 and local is not None:
            now.append(write)
        else:
            staged.model(shard, write)
    if now and local is not None:
        local.write_models(now)


def with_model(
    physics: dict[str, np.ndarray], model: dict[str, np.ndarray], lo: int, hi: int
) -> dict[str, np.ndarray]:
    """A shard's saved `physics` with the model fields of worlds lo..hi as they are now."""
    out = {k: v for k, v in physics.items() if not k.startswith(MODEL_PREFIX)}
    return out | {k: v[lo:hi] for k, v in model.items()}
