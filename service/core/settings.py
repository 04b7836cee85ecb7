"""All service settings in one place; every field can also come from an ARMFLEET_* variable.

Precedence: a `armfleet serve` option the user typed > ARMFLEET_* variable > the default here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from service.core.sim.physics import DEFAULT_PHYSICS_DT
from service.core.sim.scene_check import check_scene
from service.core.sim.types import Mode
from service.core.sim.worlds import world_list

MAX_RENDER_PIXELS = 1 << 26  # one camera's render batch: colour, depth, rays, ~12 bytes a pixel


def _cuda_device_exists(name: str, setting: str) -> None:
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


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="ARMFLEET_")

    worlds: int = Field(16, ge=1, le=1_048_576, description="number of parallel worlds")
    engine: Literal["warp", "mujoco"] = Field(
        "warp",
        description="warp: MuJoCo Warp (CPU or GPU, the default); "
        "mujoco: native MuJoCo on every CPU core (fastest on a CPU-only machine)",
    )
    device: str = Field("cpu", description="warp device: cpu, cuda or cuda:N")
    host: str = Field("127.0.0.1", description="bind address (loopback by default)")
    port: int = Field(8000, ge=0, le=65535, description="TCP port")
    shards: int = Field(
        0,
        ge=0,
        le=256,
        description="warp: CPU worker processes (one per core), mujoco: threads; 0 = auto",
    )
    engine_worker: bool = Field(
        False,
        description="warp: step the engine in a worker process of its own (always so when "
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
    scene: Path | None = Field(
        None,
        description="your cell's MJCF, which brings the arm in with <include "
        'file="ur10e_2f140.xml"/> (default: the table and cube); checked before serving',
    )
    mode: Mode = Field(Mode.REALTIME, description="how time advances: realtime, fast or paused")
    control_hz: float = Field(60.0, gt=0, le=1000, description="control ticks per second")
    physics_dt: float = Field(
        DEFAULT_PHYSICS_DT, gt=0, le=0.01, description="approximate physics step [s]"
    )
    max_body_bytes: int = Field(1 << 20, description="larger request bodies get 413")
    ws_compression: bool = Field(
        False,
        description="permessage-deflate on WebSockets (off: a 34 KB float32 pose frame costs "
        "milliseconds to deflate, per socket, and shrinks by 7%)",
    )
    log_level: Literal["debug", "info", "warning", "error"] = Field(
        "info", description="debug, info, warning or error"
    )
    # -- access (service/core/access/policy.py) --
    token: str | None = Field(
        None, description="token that writes (and with token_reads, reads) must present"
    )
    insecure: bool = Field(False, description="allow a non-loopback bind without a token")
    token_reads: bool = Field(False, description="reads need the token too")
    allow_origins: list[str] = Field(
        [],
        description="browser origins besides the service's own that may command (exact match)",
    )
    max_clients: int = Field(
        256, ge=0, description="clients served at once (HTTP requests + sockets); 0 = no limit"
    )
    command_rate: float = Field(200.0, gt=0, description="commands per second per connection")
    command_burst: int | None = Field(
        None, ge=1, description="commands a connection may send at once (default: one second's)"
    )
    leases: Literal["off", "optional", "required"] = Field(
        "off",
        description="lend worlds with tokens of their own (POST /v1/leases). optional: a leased "
        "world answers only to its lease (and --token); required: every command needs a lease "
        "token or --token",
    )
    lease_reset: Literal["both", "start", "end", "none"] = Field(
        "both", description="reset a leased world to home when its lease starts, ends, both"
    )
    lease_max_ttl_s: float = Field(
        86_400.0, gt=0, le=31 * 86_400, description="longest time to live a lease may have [s]"
    )
    data_dir: Path = Field(
        Path("~/.local/share/armfleet"), description="where snapshots and recordings are kept"
    )
    restore: str | None = Field(
        None, description="start from this snapshot: latest or a snapshot name"
    )
    save_on_exit: bool = Field(
        True, description="save snapshot `latest` on a clean stop (SIGTERM, Ctrl-C)"
    )
    record: Path | None = Field(
        None,
        description="record to this MCAP file from the start (`armfleet replay` reproduces it "
        "bit for bit on the CPU; on CUDA within a stated tolerance, see its --help)",
    )
    record_worlds: str | None = Field(
        None, description="worlds whose states are recorded, e.g. 0-7,12 (default: first 8)"
    )
    record_rate: float = Field(
        30.0, gt=0, le=1000, description="recorded states per simulated second"
    )
    record_queue: int = Field(
        2048,
        ge=16,
        le=1_000_000,
        description="items a recording may hold waiting for the disk; when full it stops",
    )
    foxglove: bool = Field(False, description="serve Foxglove's WebSocket protocol")
    foxglove_port: int = Field(8765, ge=0, le=65535, description="Foxglove WebSocket port")
    foxglove_worlds: str | None = Field(
        None, description="worlds shown in Foxglove, e.g. 0-3 (default: first 8)"
    )
    foxglove_rate: float = Field(30.0, gt=0, le=240, description="Foxglove frames per second")
    ros2: bool = Field(
        False, description="run the armfleet_ros node on the sourced ROS 2 (a supervised child)"
    )
    ros2_rate: float = Field(
        60.0,
        gt=0,
        le=1000,
        description="/joint_states, /clock and /tf rate of the ROS 2 node and rosbridge [Hz]",
    )
    ros2_worlds: str = Field(
        "", description="worlds with /world_N/ topics, e.g. 0-7 (world 0 always has /joint_*)"
    )
    ros2_python: str | None = Field(
        None, description="Python of the ROS 2 installation for --ros2 (default: the sourced one's)"
    )
    # -- cameras (core/cameras/catalog.py): the renderer is built for these once, at start --
    camera_size: str = Field(
        "128x96", description="image size of every camera, WIDTHxHEIGHT (1..4096 a side)"
    )
    camera_outputs: str = Field(
        "rgb,depth",
        description="what cameras draw unless --cameras says otherwise: rgb, depth, seg",
    )
    cameras: str = Field(
        "",
        description="per camera: NAME=WxH[:OUTPUTS] or NAME=off, comma-separated, e.g. "
        "wrist=320x240:rgb+depth,overview=off (OUTPUTS joined by +)",
    )
    camera_batch: int = Field(
        16, ge=1, le=65_536, description="worlds one render draws at once (more are drawn in turn)"
    )
    camera_device: str = Field(
        "",
        pattern=r"^(|cpu|cuda(:[0-9]+)?)$",
        description="device the cameras draw on: cpu, cuda or cuda:N, e.g. a GPU of their own "
        "beside the engine's (default: the engine's GPU; CPU engines: warp's CPU device)",
    )
    camera_rate: float = Field(
        10.0,
        gt=0,
        le=60,
        description="images a second per camera on Foxglove and in --camera-record",
    )
    foxglove_cameras: str = Field(
        "", description="cameras shown in Foxglove for --foxglove-worlds, e.g. wrist,overview"
    )
    camera_record: Path | None = Field(
        None, description="record camera images (JPEG) and calibrations to this MCAP file"
    )
    ros2_cameras: str = Field(
        "", description="cameras on the ROS 2 graph (sensor_msgs/Image + CameraInfo), e.g. wrist"
    )
    camera_record_cameras: str = Field("wrist", description="cameras --camera-record records")
    camera_record_worlds: str = Field("0", description="worlds --camera-record records, e.g. 0-3")

    @model_validator(mode="after")
    def _cameras_parse(self) -> Settings:
        from service.core.cameras.catalog import (
            parse_outputs,
            parse_overrides,
            parse_size,
            scene_cameras,
        )

        w, h = parse_size(self.camera_size, "camera_size")  # ValueError names setting + limit
        parse_outputs(self.camera_outputs, "camera_outputs")
        sizes = [(w, h)] + [c[0] for c in parse_overrides(self.cameras).values() if c and c[0]]
        biggest = max(a * b for a, b in sizes)
        if biggest * min(self.camera_batch, self.worlds) > MAX_RENDER_PIXELS:
            raise ValueError(
                f"camera_batch: {self.camera_batch} worlds of {biggest} pixels is over the "
                f"render batch's limit of {MAX_RENDER_PIXELS} pixels (~12 bytes each): "
                "lower --camera-batch or the size"
            )
        asked = {
            "cameras": list(parse_overrides(self.cameras)),
            "foxglove_cameras": self._names(self.foxglove_cameras),
            "ros2_cameras": self._names(self.ros2_cameras),
            "camera_record_cameras": self._names(self.camera_record_cameras),
        }
        have = scene_cameras()
        for setting, names in asked.items():
            unknown = [n for n in names if n not in have]
            if unknown:
                raise ValueError(
                    f"{setting}: the scene has no camera {unknown[0]!r} (it has: {', '.join(have)})"
                )
        if self.camera_record:
            world_list(self.camera_record_worlds, self.worlds, "camera_record_worlds")
        if self.camera_device.startswith("cuda"):
            _cuda_device_exists(self.camera_device, "camera_device")
        return self

    def engine_apart(self) -> bool:
        """Whether the warp engine steps in a worker process of its own: asked for, or the
        cameras draw on another device. Warp's default device is one per process, so a
        renderer on cuda:1 and an engine on cuda:0 (or the CPU) cannot share one process."""
        if self.engine != "warp" or self.ray:
            return False  # native MuJoCo has no warp device; Ray's shards are apart already

        def named(device: str) -> str:
            return "cuda:0" if device == "cuda" else device

        engine = named(self.device if self.device.startswith("cuda") else "cpu")
        return self.engine_worker or named(self.camera_device or engine) != engine

    @staticmethod
    def _names(text: str) -> list[str]:
        return [p.strip() for p in text.split(",") if p.strip()]

    @model_validator(mode="after")
    def _ray_runs_the_warp_engine(self) -> Settings:
        if self.ray and self.engine != "warp":
            raise ValueError("ray: Ray actors run the warp engine only (use --engine warp)")
        if self.engine_worker and (self.engine != "warp" or self.ray):
            raise ValueError(
                "engine_worker: a worker process holds the warp engine only, and not with "
                "--ray (its actors are processes of their own already)"
            )
        return self

    @model_validator(mode="after")
    def _required_leases_have_an_administrator(self) -> Settings:
        if self.leases == "required" and not self.token:
            raise ValueError("leases required: give --token, the administrator's (who lends)")
        return self

    @model_validator(mode="after")
    def _scene_can_be_served(self) -> Settings:
        if self.scene is not None:
            check_scene(self.scene)  # SceneError (a ValueError) says what is wrong
        return self

    @model_validator(mode="after")
    def _ros2_worlds_exist(self) -> Settings:
        world_list(self.ros2_worlds, self.worlds, "ros2_worlds")  # ValueError names the bad part
        return self
