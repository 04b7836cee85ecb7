"""What persistence is asked to keep: where snapshots and recordings live, the snapshot to
start from, whether `latest` is saved on a clean stop, and the `--record` recording. Why a
model of its own: `Persistence` (service.py) reads these and nothing else.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field


class PersistenceSettings(BaseModel):
    """Snapshots and recordings (`--data-dir`, `--restore`, `--save-on-exit`, `--record*`)."""

    model_config = ConfigDict(extra="forbid")

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
