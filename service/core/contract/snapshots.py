"""Snapshots and recordings on the API: a snapshot as listed (with the randomisations it
holds), a restore's reply, and the request bodies and status of snapshots and recordings."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field

from service.core.commands.fields import Strict
from service.core.sim.worlds import WORLDS_PATTERN


class RandomizationGroup(BaseModel):
    """Worlds that share one randomisation (POST /v1/randomize): its seed, spec and tick."""

    worlds: list[int]
    tick: int = Field(description="the first tick stepped from the drawn worlds")
    seed: int
    spec: dict[str, Any]


class SnapshotInfo(BaseModel):
    """One saved snapshot as listed: name, bytes on disk, when, at which tick, of which batch,
    and per world the last randomisation its state holds (service/persistence/snapshots.py
    makes them)."""

    model_config = ConfigDict(frozen=True)

    name: str
    size_bytes: int
    created: str = Field(description="UTC, ISO 8601")
    tick: int = Field(description="batch tick the snapshot was taken at")
    nworld: int
    model_hash: str = Field(description="sha256 of the compiled model (MJB)")
    format: str = Field("", description="the file's format and version")
    randomization: list[RandomizationGroup] = Field(
        default_factory=list,
        description="the last randomisation of each world, worlds sharing one grouped; a "
        "world in no group had none (or the file is older than this field)",
    )


class RestoreReply(BaseModel):
    name: str
    tick: int = Field(description="the tick the batch continues from")


class WorldRandomization(BaseModel):
    """One world's last randomisation as of `tick` (seed and spec null when it had none)."""

    world: int
    tick: int = Field(description="the tick this answer is of")
    randomized_at: int | None = Field(description="the tick the randomisation took effect at")
    seed: int | None
    spec: dict[str, Any] | None


# -- snapshots and recordings -----------------------------------------------------------------

# Names become file names under the data directory (see service/persistence/snapshots.py).
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


class SnapshotRequest(Strict):
    name: SnapshotName

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"name": "before"}]})


class RecordingRequest(Strict):
    name: SnapshotName = Field(description="file <data-dir>/recordings/<name>.mcap")
    worlds: str | None = Field(
        default=None,
        pattern=WORLDS_PATTERN,
        description="worlds whose states are recorded, e.g. '0-7,12'; default first 8",
    )
    # At least one state per 1000 simulated seconds: a rate of 5e-324 made `every_ticks`
    # infinite and the start a 500 (found by schemathesis, issue 38).
    rate: float = Field(default=30.0, ge=0.001, le=1000, description="states per simulated second")

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"name": "run1", "worlds": "0-3", "rate": 30}]},
    )


class RecordingStatus(BaseModel):
    """What GET /v1/recordings/current shows (service/persistence/recorder.py makes it)."""

    path: str
    worlds: list[int]
    every_ticks: int = Field(description="a state every this many ticks")
    start_tick: int
    active: bool = Field(description="still writing")
    written: int = Field(description="items written so far")
    error: str | None = Field(description="why the recording stopped early, if it did")
