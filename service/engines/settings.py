"""What the engine is asked to be: which engine, on which device, in how many shards, where.

Why a model of its own: `engines/choice.py` builds the batch from these and the simulation's
settings alone. It imports no engine: a device the machine lacks is found where the engine
starts (`choice.check_devices`), not while the settings are read. A field's `validation_alias`
is its flat name (`ARMFLEET_ENGINE`, `--engine-worker`), kept from the flat model of before.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field, model_validator

from service.core.process.flat_names import BY_BOTH, flat


def cuda_name(device: str) -> str:
    """`cuda` is `cuda:0`: the name two devices are compared by."""
    return "cuda:0" if device == "cuda" else device


class EngineSettings(BaseModel):
    """The engine (`--engine`, `--device`, `--shards`, `--engine-worker`, `--ray`, ...)."""

    model_config = BY_BOTH

    kind: Literal["warp", "mujoco"] = flat(
        "engine",
        "warp",
        "warp: MuJoCo Warp (CPU or GPU, the default); "
        "mujoco: native MuJoCo on every CPU core (fastest on a CPU-only machine)",
    )
    device: str = Field("cpu", description="warp device: cpu, cuda or cuda:N")
    shards: int = Field(
        0,
        ge=0,
        le=256,
        description="warp: CPU worker processes (one per core), mujoco: threads; 0 = auto",
    )
    worker: bool = flat(
        "engine_worker",
        False,
        "warp: step the engine in a worker process of its own (always so when "
        "--camera-device names another device); the server outlives an engine crash, and the "
        "engine is rebuilt from its last state copy",
    )
    ray: str | None = Field(
        None,
        description="put the shards on Ray actors: auto (the cluster `ray start` runs here), "
        "local (a private instance on 127.0.0.1) or HOST:PORT of a head node; "
        "unset = in-process shards",
    )
    ray_checkpoint_s: float = Field(
        10.0,
        gt=0,
        description="--ray: seconds between copies of each shard's state into this process; a "
        "shard whose node is lost is rebuilt elsewhere from its last copy",
    )

    @model_validator(mode="after")
    def _ray_runs_the_warp_engine(self) -> EngineSettings:
        if self.ray and self.kind != "warp":
            raise ValueError("ray: Ray actors run the warp engine only (use --engine warp)")
        if self.worker and (self.kind != "warp" or self.ray):
            raise ValueError(
                "engine_worker: a worker process holds the warp engine only, and not with "
                "--ray (its actors are processes of their own already)"
            )
        return self

    def apart(self, camera_device: str = "") -> bool:
        """Whether the warp engine steps in a worker process of its own: asked for, or the
        cameras draw on another device (`camera_device`, empty: the engine's). Warp's default
        device is one per process, so a renderer on cuda:1 and an engine on cuda:0 (or the
        CPU) cannot share one process."""
        if self.kind != "warp" or self.ray:
            return False  # native MuJoCo has no warp device; Ray's shards are apart already
        engine = cuda_name(self.device if self.device.startswith("cuda") else "cpu")
        return self.worker or cuda_name(camera_device or engine) != engine
