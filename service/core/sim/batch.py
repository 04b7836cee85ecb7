"""The engine protocol: what the loop needs of an engine, and what some engines can do besides.

`Batch` is what every engine implements. Commands reach an engine through one door,
`Batch.write(TickWrites)`, once per tick boundary: whatever a command changes (targets and
their feed-forward, resets, a slice of a world's qpos/qvel) is a field of `TickWrites`, so a new
command that writes state the engines already hold needs no change in any engine. Optional
capabilities are protocols of their own (`Restorable`: save and restore the full state;
`Supervised`: workers that can be lost and are rebuilt; `PacksFrames`: gathers stream rows on
its side; `SnapshotsBeside`: a snapshot's copy beside the next tick; `Renderable`: hands the
cameras the state of some worlds), checked with `isinstance`,
so that a caller never guesses from attributes or bodies.
Lives in the core with the types it speaks in; imports nothing above the core.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, Protocol, Self, runtime_checkable

import numpy as np

from service.core.sim.robot import LoadedRobot
from service.core.sim.types import NJOINT, BatchState, RobotSpec, Snapshot

if TYPE_CHECKING:
    from service.core.sim.packed_rows import PackedRows

_NO_WORLDS = np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class WorldWrite:
    """Values for some addresses of one world's row of one engine array (`StateWrite`,
    `ModelWrite`): field: the array; world: its id; index: addresses in that world's row
    (m,) int64; values: (m,) float64. Built by a command that validated it."""

    field: str
    world: int
    index: np.ndarray
    values: np.ndarray

    def moved(self, world: int) -> Self:
        """The same write for world id `world` (a shard's local id)."""
        return dataclasses.replace(self, world=world)


@dataclass(frozen=True)
class StateWrite(WorldWrite):
    """Values for some addresses of one world's qpos or qvel (a free body's pose or twist);
    the addresses are its entity's."""

    field: Literal["qpos", "qvel"]


@dataclass(frozen=True)
class ModelWrite(WorldWrite):
    """Values for some entries of one world's copy of one MjModel array field (a per-world
    physics parameter: a body's mass, a geom's friction, a joint's damping, a servo's gain);
    `field` is the MjModel field, e.g. "body_mass", and `index` flat addresses into that
    world's row of it. Model values stay through resets: they describe the world, not its
    state."""


@dataclass(frozen=True)
class TickWrites:
    """Everything the commands of one tick boundary write into an engine, applied in this
    order: `resets` (worlds back at home), then `model` and `state` (in the order staged), then
    targets.

    resets: worlds reset to home                                        (r,) int64
    worlds: worlds whose targets changed                                (k,) int64
    targets: their targets, already clamped by the command [rad]        (k, 7) float64
    velocities: their velocity feed-forward [rad/s], None = zero        (k, 7) float64
    state: qpos/qvel slices, applied after the resets
    model: per-world model field values, applied after the resets, before `state`
    """

    resets: np.ndarray = field(default_factory=lambda: _NO_WORLDS)
    worlds: np.ndarray = field(default_factory=lambda: _NO_WORLDS)
    targets: np.ndarray = field(default_factory=lambda: np.zeros((0, NJOINT)))
    velocities: np.ndarray | None = None
    state: tuple[StateWrite, ...] = ()
    model: tuple[ModelWrite, ...] = ()

    def __bool__(self) -> bool:
        return bool(self.resets.size or self.worlds.size or self.state or self.model)


@runtime_checkable
class Batch(Protocol):
    """N worlds of one model advanced together in control ticks: what the loop needs of an engine.

    WorldBatch (MuJoCo Warp on one device), NativeBatch (native MuJoCo), ShardedBatch (worlds
    split over worker processes) and RayBatch (over Ray actors) implement it; so must any later
    engine. What only some engines can do is a capability below, checked with `isinstance`.
    One thread owns a Batch: nothing here is thread-safe.
    tests/test_batch_contract.py runs the same behavioural checks against every implementation.
    """

    nworld: int  # worlds in the batch
    shards: int  # processes (or actors) the worlds are split across
    spec: RobotSpec  # the commanded joints, limits and home
    robot: LoadedRobot  # the compiled MjModel it steps (viewers describe it: GET /v1/scene)
    control_hz: float  # control ticks per simulated second
    tick_dt: float  # simulated seconds per tick (1 / control_hz)
    substeps: int  # physics steps per tick
    physics_dt: float  # simulated seconds per physics step (tick_dt / substeps)
    device_name: str  # where it runs, e.g. "cpu" or "cuda:0"
    home_target: np.ndarray  # (7,) targets of the `home` keyframe [rad]
    captured: bool  # the tick replays a captured graph
    capture_error: str | None  # why capture failed, when it did
    compile_s: float  # seconds spent compiling/loading kernels at build
    capture_s: float  # seconds spent capturing the tick, at build and since

    @property
    def tick(self) -> int:
        """Control ticks completed since the batch was built."""
        ...

    @property
    def targets(self) -> np.ndarray:
        """A copy of the targets in effect, (nworld, 7) [rad]."""
        ...

    def step(self, ticks: int = 1) -> np.ndarray:
        """Advance every world by `ticks`; returns the worlds reset for faults (int64)."""
        ...

    def write(self, writes: TickWrites) -> None:
        """Apply one tick boundary's commands (see `TickWrites`), in effect from the next step."""
        ...

    def write_state(self, write: StateWrite) -> None:
        """Overwrite some qpos/qvel addresses of one world now (part of `write`)."""
        ...

    def write_models(self, writes: Sequence[ModelWrite]) -> None:
        """Give worlds their own values of some model field entries now (part of `write`), and
        recompute what MuJoCo derives from them (mj_setConst) per world."""
        ...

    def model_values(self, field: str) -> np.ndarray:
        """Every world's values of an MjModel field (nworld, ...), float64, a host copy: the
        scene's own where no command wrote it."""
        ...

    def apply_targets(
        self, worlds: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None = None
    ) -> None:
        """Targets for `worlds` (k,) ← `targets` (k, 7) as given (commands clamp them), in effect
        from the next step (part of `write`).

        `velocities` (k, 7) [rad/s]: a velocity feed-forward for the servos (trajectories send
        their desired velocity, so tracking has no kv/kp × speed lag); None sets it to zero,
        and with zero feed-forward every engine steps exactly as with targets alone.
        """
        ...

    def reset(self, worlds: np.ndarray) -> None:
        """Reset `worlds` to `home` (state and targets); every other world stays bit-identical."""
        ...

    def snapshot(self) -> Snapshot:
        """All worlds at the end of the last completed tick, in host memory."""
        ...

    def qpos(self) -> np.ndarray:
        """Full qpos of every world (nworld, nq), a host copy (tests and diagnostics)."""
        ...

    def qvel(self) -> np.ndarray:
        """Full qvel of every world (nworld, nv), a host copy (tests and diagnostics)."""
        ...

    def write_qpos(self, world: int, qpos: np.ndarray) -> None:
        """Overwrite one world's full qpos (nq,): tests inject faults with it."""
        ...

    def close(self) -> None:
        """Release workers and devices; the batch is unusable afterwards."""
        ...


@runtime_checkable
class Restorable(Protocol):
    """An engine that can hand out its full state and continue from one (snapshots, recordings,
    `--restore`): every engine in the tree is one; a later engine may not be yet."""

    def physics_shapes(self) -> dict[str, tuple[int, ...]]:
        """Per-world shape of each `PHYSICS_FIELDS` array this batch holds."""
        ...

    def get_state(self) -> BatchState:
        """Everything needed to continue bit-identically (see `BatchState`), host copies."""
        ...

    def set_state(self, state: BatchState) -> None:
        """Continue from `state` (same model and nworld); ValueError naming the mismatch, and
        nothing changed, when it does not fit."""
        ...


@runtime_checkable
class Supervised(Protocol):
    """An engine whose workers can be lost and are rebuilt (process shards): it reports what is
    wrong now (shown by /readyz) and how often a worker was rebuilt (a metric)."""

    restarts: int  # workers rebuilt since the batch was built

    def health(self) -> list[str]:
        """What is wrong now (a lost shard, a rebuild under way); empty when all is well."""
        ...


@runtime_checkable
class PacksFrames(Protocol):
    """An engine that gathers the stream rows of chosen worlds on its side (a kernel and one
    pinned copy on a GPU, copies between ticks on the CPU) instead of a full snapshot."""

    def pack_rows(self, ids: np.ndarray) -> PackedRows | None:
        """The binary rows of worlds `ids` at the last tick (None: no buffer free now)."""
        ...

    def host_columns(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sim_time [s] float64, targets (k, 7) float64, faults int64) of `ids`, host copies."""
        ...


@runtime_checkable
class SnapshotsBeside(Protocol):
    """An engine whose snapshot can reach the host beside the next tick (on a GPU: a copy on the
    device now, the copy to the host on a side stream while the next tick runs). The loop takes
    its periodic snapshot, which nobody waits for, this way: the tick is not held up for it."""

    def snapshot_beside(self) -> tuple[Snapshot, Callable[[], None]] | None:
        """`snapshot()` of the last tick, its arrays valid once the callable (a wait) returned;
        None when this engine or this moment gains nothing by it: take `snapshot()`."""
        ...


@runtime_checkable
class SteppedBeside(Protocol):
    """An engine that steps on threads or processes of its own beside the loop's thread (a
    pool, shard workers): the loop raises their priority with its own in real time
    (service/core/process/engine_priority.py)."""

    def stepping_ids(self) -> tuple[int, ...]:
        """The thread ids (this process) and process ids (workers) that step worlds now."""
        ...


@runtime_checkable
class Renderable(Protocol):
    """An engine whose worlds cameras can see: between two ticks (on the loop's thread) it hands
    over the positions of the asked worlds, and the batch renderer draws them on a thread of
    its own, so that a picture costs the loop one small copy, not the drawing."""

    def render_state(self, worlds: np.ndarray) -> np.ndarray:
        """qpos of `worlds` (k,) at the end of the last tick, (k, nq), a host copy."""
        ...
