"""The wire contract: pydantic models for every HTTP body and WebSocket message.

Numbers are finite floats (NaN/Inf are refused at the edge, before anything is staged).
Joint-state fields follow sensor_msgs/JointState (`name`, `position`, `velocity`, `effort`).
"""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator

from service.types import JointSpec, Mode

# Strict: numbers only ("0.1" and true are refused); ints are fine.
FiniteFloat = Annotated[float, Field(allow_inf_nan=False, strict=True)]
JointRef = Annotated[str | int, Field(description="joint name or index 0..6")]
Delta = Annotated[
    float,
    Field(
        allow_inf_nan=False,
        strict=True,
        ge=-2 * math.pi,
        le=2 * math.pi,
        description="rad, |delta| <= 2π",
    ),
]
MAX_STEP_TICKS = 100_000


def _paired(keys_name: str, keys: list, values_name: str, values: list) -> None:
    """Parallel lists (JointState's name/position, worlds/position): same length, keys unique."""
    if len(keys) != len(values):
        raise ValueError(
            f"{keys_name} and {values_name} must have the same length "
            f"(got {len(keys)} and {len(values)})"
        )
    if len(set(keys)) != len(keys):
        raise ValueError(f"{keys_name} lists an entry twice")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


# -- replies ----------------------------------------------------------------------------------


class Info(BaseModel):
    robot: str
    joints: list[JointSpec] = Field(description="the commanded joints, in command order")
    nworld: int
    device: str
    shards: int = Field(description="processes the worlds are split across (CPU cores used)")
    control_hz: float
    physics_dt: float
    substeps: int
    mode: Mode
    tick: int
    sim_time: float = Field(description="tick / control_hz: simulated seconds since start")
    ticks_per_s: float = Field(description="measured over the last second")
    realtime_factor: float = Field(description="simulated seconds per wall second")
    captured: bool = Field(description="the control tick replays a captured graph")


class Flange(BaseModel):
    position: list[float] = Field(description="x y z [m], world frame")
    quaternion: list[float] = Field(description="w x y z")


class WorldState(BaseModel):
    """sensor_msgs/JointState fields plus the target in effect and the flange pose."""

    world: int
    tick: int
    sim_time: float = Field(description="simulated seconds since this world's last reset")
    name: list[str]
    position: list[float]
    velocity: list[float]
    effort: list[float]
    target: list[float]
    flange: Flange
    faults: int = Field(description="times this world was reset for NaN or capacity overflow")


class WorldStates(BaseModel):
    tick: int
    worlds: list[WorldState]


class CommandReply(BaseModel):
    world: int
    target: list[float] = Field(description="the world's 7 targets after this command [rad]")
    clamped: list[str] = Field(description="joints whose target hit a range limit")
    tick: int = Field(description="first tick stepped with this command")


class BatchCommandReply(BaseModel):
    tick: int
    results: list[CommandReply]


class ResetReply(BaseModel):
    worlds: list[int]
    tick: int


class SimReply(BaseModel):
    mode: Mode
    tick: int


# -- requests ---------------------------------------------------------------------------------


class IncrementRequest(_Strict):
    """One joint (`joint` + `delta`) or several (`deltas`): the seed's Up/Down buttons."""

    joint: JointRef | None = None
    delta: Delta | None = None
    deltas: dict[str, Delta] | None = None

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {"joint": "elbow_joint", "delta": 0.1},
                {"deltas": {"elbow_joint": 0.1, "finger_joint": -0.1}},
            ]
        },
    )

    @model_validator(mode="after")
    def _one_form(self) -> IncrementRequest:
        single = self.joint is not None or self.delta is not None
        if single == (self.deltas is not None):
            raise ValueError("give either `joint` and `delta`, or `deltas`")
        if single and (self.joint is None or self.delta is None):
            raise ValueError("`joint` and `delta` go together")
        return self

    def as_mapping(self) -> dict[str | int, float]:
        if self.deltas is not None:
            return dict(self.deltas)
        assert self.joint is not None and self.delta is not None
        return {self.joint: self.delta}


class JointTargets(_Strict):
    """sensor_msgs/JointState-shaped: a subset of names is allowed; others keep their targets."""

    name: list[str] = Field(min_length=1, max_length=7)
    position: list[FiniteFloat] = Field(min_length=1, max_length=7)

    model_config = ConfigDict(
        extra="allow",  # JointState also carries header/velocity/effort; they are ignored
        json_schema_extra={
            "examples": [{"name": ["elbow_joint", "finger_joint"], "position": [1.2, 0.35]}]
        },
    )

    @model_validator(mode="after")
    def _same_length(self) -> JointTargets:
        _paired("name", self.name, "position", self.position)
        return self


class BatchTargets(_Strict):
    """Full 7-joint targets for many worlds in one request, applied at one tick boundary."""

    worlds: list[int] = Field(min_length=1)
    position: list[Annotated[list[FiniteFloat], Field(min_length=7, max_length=7)]]

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [{"worlds": [0, 1], "position": [[0, -1.57, 1.57, -1.57, -1.57, 0, 0]] * 2}]
        },
    )

    @model_validator(mode="after")
    def _same_length(self) -> BatchTargets:
        _paired("worlds", self.worlds, "position", self.position)
        return self


class ResetRequest(_Strict):
    worlds: list[int] | None = Field(default=None, description="omit for all worlds")

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"worlds": [0, 3]}]})


class ModeRequest(_Strict):
    mode: Mode

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"mode": "fast"}]})


class StepRequest(_Strict):
    ticks: int = Field(default=1, ge=1, le=MAX_STEP_TICKS)

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"ticks": 60}]})


# -- snapshots and recordings -----------------------------------------------------------------

# Names become file names under the data directory (see service/snapshots.py).
SNAPSHOT_NAME = r"^[A-Za-z0-9_][A-Za-z0-9._-]{0,63}$"
SnapshotName = Annotated[
    str,
    Field(
        pattern=SNAPSHOT_NAME,
        min_length=1,
        max_length=64,
        description="1-64 letters, digits, '.', '_', '-'; not starting with '.' or '-'",
    ),
]


class SnapshotRequest(_Strict):
    name: SnapshotName

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"name": "before"}]})


class SnapshotInfo(BaseModel):
    name: str
    size_bytes: int
    created: str = Field(description="UTC, ISO 8601")
    tick: int = Field(description="batch tick the snapshot was taken at")
    nworld: int
    model_hash: str = Field(description="sha256 of the compiled model (MJB)")


class RestoreReply(BaseModel):
    name: str
    tick: int = Field(description="the tick the batch continues from")


class RecordingRequest(_Strict):
    name: SnapshotName = Field(description="file <data-dir>/recordings/<name>.mcap")
    worlds: str | None = Field(
        default=None, description="worlds whose states are recorded, e.g. '0-7,12'; default first 8"
    )
    rate: float = Field(default=30.0, gt=0, le=1000, description="states per simulated second")

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"name": "run1", "worlds": "0-3", "rate": 30}]},
    )


class RecordingStatus(BaseModel):
    path: str
    worlds: list[int]
    every_ticks: int = Field(description="a state every this many ticks")
    start_tick: int
    active: bool = Field(description="still writing")
    written: int = Field(description="items written so far")
    error: str | None = Field(description="why the recording stopped early, if it did")


# -- the drawable scene (GET /v1/scene; built by service/scene.py) ------------------------------


class SceneBody(BaseModel):
    id: int = Field(description="MjModel body index; row of the pose frames' body axis")
    name: str
    parent: int = Field(description="parent body id (the world body, 0, is its own parent)")


class SceneMesh(BaseModel):
    vertices: list[float] = Field(description="x y z per vertex, flattened [m], geom frame")
    faces: list[int] = Field(description="3 vertex indices per triangle, flattened")


class SceneGeom(BaseModel):
    """One visible geom, described in its body's frame as MuJoCo compiled it."""

    id: int = Field(description="MjModel geom index")
    name: str = Field(description="empty when the MJCF gave none")
    body: int = Field(description="body the geom is attached to")
    type: str = Field(description="plane, sphere, capsule, ellipsoid, cylinder, box or mesh")
    size: list[float] = Field(
        description="MuJoCo geom_size [m]: box half-extents; sphere radius; capsule/cylinder "
        "radius and half-length along the local z axis; plane half-sizes (0 = infinite)"
    )
    pos: list[float] = Field(description="x y z in the body frame [m]")
    quat: list[float] = Field(description="orientation in the body frame, w x y z")
    rgba: list[float] = Field(description="colour, 0..1 (the material's when it has one)")
    mesh: SceneMesh | None = Field(None, description="mesh geoms only")


class Scene(BaseModel):
    nbody: int = Field(description="bodies per world in the pose frames (world body included)")
    bodies: list[SceneBody]
    geoms: list[SceneGeom] = Field(description="geoms of groups 0-2 (MuJoCo's visible groups)")
    skipped: int = Field(description="visible geoms of types not described (height fields, SDFs)")
