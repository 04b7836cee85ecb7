"""The engine protocol: what the loop needs of an engine, and what some engines can do besides.

`Batch` is what every engine implements. Optional capabilities are protocols of their own
(`Restorable`: save and restore the full state; `Supervised`: workers that can be lost and are
rebuilt; `Renderable`: hands the cameras the state of some worlds), checked with `isinstance`,
so that a caller never guesses from attributes or bodies.
Lives in the core with the types it speaks in; imports nothing above the core.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from service.core.robot import LoadedRobot
from service.core.types import BatchState, RobotSpec, Snapshot


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
    capture_s: float  # seconds spent capturing the tick at build

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

    def apply_targets(
        self, worlds: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None = None
    ) -> None:
        """Targets for `worlds` (k,) ← `targets` (k, 7), clamped, in effect from the next step.

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
class Renderable(Protocol):
    """An engine whose worlds cameras can see: between two ticks (on the loop's thread) it hands
    over the positions of the asked worlds, and the batch renderer draws them on a thread of
    its own, so that a picture costs the loop one small copy, not the drawing."""

    def render_state(self, worlds: np.ndarray) -> np.ndarray:
        """qpos of `worlds` (k,) at the end of the last tick, (k, nq), a host copy."""
        ...
