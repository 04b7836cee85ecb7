"""The Ray side of RayBatch: joining a cluster, the actor one shard of worlds lives in, and
the driver's record of each shard.

An actor holds a WorldBatch of its block of worlds and answers the calls RayBatch (ray_shards.py)
makes each tick; it knows nothing of the other shards.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import ray

from service.core.sim.types import BatchState
from service.engines.sharding import Shipment, apply_and_step
from service.engines.shards import MIN_WORLDS_PER_SHARD
from service.engines.warp import WorldBatch
from service.engines.warp_snapshot import SnapshotArrays

# The directory that holds the `service` package: actors import it from there when the node has
# the same checkout (one machine, or a shared path); elsewhere armfleet must be installed.
_CODE_ROOT = str(Path(__file__).resolve().parents[2])
# A private local instance ("local") gets a small object store: snapshots are the largest
# objects (28 float64 per world) and are freed as soon as they are read.
_LOCAL_OBJECT_STORE_BYTES = 256 << 20


def connect(address: str, num_cpus: int | None = None, num_gpus: int | None = None) -> None:
    """Join the Ray cluster named by `address`, once per process.

    auto: the cluster that `ray start --head` runs on this machine;
    local: a private instance for this process only, bound to 127.0.0.1, no dashboard;
    HOST:PORT or ray://HOST:PORT: a cluster's head node.
    num_cpus, num_gpus: what a "local" instance offers (None: what Ray detects).
    """
    if ray.is_initialized():
        return
    path = [p for p in (_CODE_ROOT, os.environ.get("PYTHONPATH")) if p]
    env = {"PYTHONPATH": os.pathsep.join(path)}
    os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    if address == "local":
        ray.init(
            address="local",
            num_cpus=num_cpus,
            num_gpus=num_gpus,
            include_dashboard=False,
            _node_ip_address="127.0.0.1",
            object_store_memory=_LOCAL_OBJECT_STORE_BYTES,
            runtime_env={"env_vars": env},
            log_to_driver=True,
        )
    else:
        ray.init(address=address, runtime_env={"env_vars": env}, log_to_driver=True)


def ray_auto_shards(nworld: int, device: str) -> int:
    """One shard per GPU of the cluster on CUDA, else one per CPU core (big enough batches)."""
    resources = ray.cluster_resources()
    if device.startswith("cuda"):
        gpus = int(resources.get("GPU", 0))
        if gpus < 1:
            raise RuntimeError("device is cuda but the Ray cluster has no GPUs")
        return max(1, min(gpus, nworld))
    cpus = int(resources.get("CPU", 1))
    return max(1, min(cpus, nworld // MIN_WORLDS_PER_SHARD))


class ShardActor:
    """A shard's side: a WorldBatch of its worlds, stepped with the commands the driver staged.

    Ray instantiates it as an actor (`ray.remote(ShardActor)`), one process per shard.
    """

    def __init__(self, nworld: int, kwargs: dict[str, Any]) -> None:
        self._batch = WorldBatch(nworld, **kwargs)

    def info(self) -> dict[str, Any]:
        """What the driver reports about the engine (the same for every shard)."""
        b = self._batch
        return {
            "spec": b.spec,
            "control_hz": b.control_hz,
            "tick_dt": b.tick_dt,
            "substeps": b.substeps,
            "physics_dt": b.physics_dt,
            "device_name": b.device_name,
            "home_target": b.home_target,
            "captured": b.captured,
            "capture_error": b.capture_error,
            "compile_s": b.compile_s,
            "capture_s": b.capture_s,
            "physics_shapes": b.physics_shapes(),
            "node": ray.get_runtime_context().get_node_id(),
        }

    def step(self, shipment: Shipment, ticks: int) -> tuple[np.ndarray, float]:
        """Apply the staged commands, step; (faulted local ids, seconds the shard spent)."""
        t0 = time.perf_counter()
        faulted = apply_and_step(self._batch, shipment, ticks)
        return faulted, time.perf_counter() - t0

    def snapshot(self) -> SnapshotArrays:
        """Contiguous arrays, not a Snapshot: Ray ships them without copying field by field."""
        return self._batch.snapshot_arrays()

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        return self._batch.qpos(), self._batch.qvel()

    def write_qpos(self, world: int, qpos: np.ndarray) -> None:
        self._batch.write_qpos(world, qpos)

    def get_state(self, shipment: Shipment) -> BatchState:
        """The shard's state after the commands staged for it (a step of zero ticks)."""
        apply_and_step(self._batch, shipment, 0)
        return self._batch.get_state()

    def set_state(self, state: BatchState) -> None:
        self._batch.set_state(state)


RemoteShard = ray.remote(ShardActor)


@dataclass
class Shard:
    """The driver's view of one shard: its actor, and while it is being rebuilt, its readiness."""

    actor: Any
    last: SnapshotArrays | None = None  # the shard's last snapshot, shown while it is rebuilt
    building: Any = None  # ObjectRef of the new actor's info() while it is being built
    failures: int = 0  # consecutive failed builds
    checkpoint: BatchState | None = None  # the shard's last state copied here (CHECKPOINT_S)
    lost: list[float] = field(default_factory=list)  # wall times at which the actor was lost


class _Never:
    """Stands in for a build that will not be retried: never ready, so the shard stays frozen."""


NEVER = _Never()
