"""The engine the settings ask for: the one place that maps settings to a `Batch`.

Each engine is imported only when chosen, so that the native engine never loads Warp and Ray is
imported only for `--ray`. The CUDA devices the settings name are checked here too
(`check_devices`), before serving: the settings themselves import no engine.
"""

from __future__ import annotations

from service.core.sim.batch import Batch
from service.core.sim.settings import SimSettings
from service.engines.settings import EngineSettings


def cuda_device_exists(name: str, setting: str) -> None:
    """ValueError naming `setting` when this machine has no CUDA device `name` (cuda, cuda:N).
    Warp is started only here, when a setting names a CUDA device."""
    import warp as wp

    index = int(name.partition(":")[2] or 0)
    level, wp.config.log_level = wp.config.log_level, wp.LOG_WARNING  # no banner first
    try:
        count = wp.get_cuda_device_count()
    finally:
        wp.config.log_level = level
    if index >= count:
        have = ", ".join(f"cuda:{i}" for i in range(count)) or "none"
        raise ValueError(f"{setting}: no CUDA device {name!r} on this machine (it has: {have})")


def check_devices(camera_device: str) -> None:
    """ValueError (naming the setting and the devices there are) when the cameras are asked
    to draw on a CUDA device this machine lacks; called as the service is created, before it
    serves (the engine's own `--device` is checked by Warp as the engine is built)."""
    if camera_device.startswith("cuda"):
        cuda_device_exists(camera_device, "camera_device")


def build_batch(engine: EngineSettings, sim: SimSettings, camera_device: str = "") -> Batch:
    """Native MuJoCo on every core (`--engine mujoco`), or MuJoCo Warp: on Ray actors
    (`--ray`), in worker processes only (`EngineSettings.apart`: the cameras on another
    device `camera_device`, or asked), split over CPU worker processes when it pays, or one
    batch."""
    scene = {"model_path": sim.scene} if sim.scene is not None else {}
    if engine.kind == "mujoco":
        from service.engines.native import NativeBatch

        return NativeBatch(
            sim.worlds,
            control_hz=sim.control_hz,
            physics_dt=sim.physics_dt,
            nthread=engine.shards,
            device=engine.device,
            **scene,
        )
    from service.engines.shards import ShardedBatch, auto_shards
    from service.engines.warp import WorldBatch

    shards = engine.shards or auto_shards(sim.worlds, engine.device)
    kwargs = {
        "device": engine.device,
        "control_hz": sim.control_hz,
        "physics_dt": sim.physics_dt,
        **scene,
    }
    if engine.ray:
        from service.engines import ray_local
        from service.engines.ray_shards import RayBatch  # imports Ray only when asked for

        with ray_local.starting():  # what Ray starts leaves stopping to us (core/stopping)
            return RayBatch(
                sim.worlds,
                engine.shards,
                address=engine.ray,
                checkpoint_s=engine.ray_checkpoint_s,
                **kwargs,
            )
    if engine.apart(camera_device):  # every shard in a worker: nothing of the engine here
        return ShardedBatch(sim.worlds, shards, local=False, **kwargs)
    if shards > 1:
        return ShardedBatch(sim.worlds, shards, **kwargs)
    return WorldBatch(sim.worlds, **kwargs)
