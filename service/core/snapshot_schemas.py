"""Snapshot replies of the API: a snapshot as listed (with the randomisations it holds), and a
restore's reply. Kept apart from schemas.py, which the per-world schemas fill."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field


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
