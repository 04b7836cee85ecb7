"""The engine the settings ask for: the one place that maps settings to a `Batch`.

Each engine is imported only when chosen, so that the native engine never loads Warp and Ray is
imported only for `--ray`.
"""

from __future__ import annotations

from service.core.settings import Settings
from service.core.sim.batch import Batch


def build_batch(s: Settings) -> Batch:
    """Native MuJoCo on every core (`--engine mujoco`), or MuJoCo Warp: on Ray actors
    (`--ray`), in worker processes only (`Settings.engine_apart`: the cameras on another
    device, or asked), split over CPU worker processes when it pays, or one batch."""
    scene = {"model_path": s.scene} if s.scene is not None else {}
    if s.engine == "mujoco":
        from service.engines.native import NativeBatch

        return NativeBatch(
            s.worlds,
            control_hz=s.control_hz,
            physics_dt=s.physics_dt,
            nthread=s.shards,
            device=s.device,
            **scene,
        )
    from service.engines.shards import ShardedBatch, auto_shards
    from service.engines.warp import WorldBatch

    shards = s.shards or auto_shards(s.worlds, s.device)
    kwargs = {"device": s.device, "control_hz": s.control_hz, "physics_dt": s.physics_dt, **scene}
    if s.ray:
        from service.engines import ray_local
        from service.engines.ray_shards import RayBatch  # imports Ray only when asked for

        with ray_local.starting():  # what Ray starts leaves stopping to us (core/stopping)
            return RayBatch(
                s.worlds, s.shards, address=s.ray, checkpoint_s=s.ray_checkpoint_s, **kwargs
            )
    if s.engine_apart():  # every shard in a worker: nothing of the engine in this process
        return ShardedBatch(s.worlds, shards, local=False, **kwargs)
    if shards > 1:
        return ShardedBatch(s.worlds, shards, **kwargs)
    return WorldBatch(s.worlds, **kwargs)
