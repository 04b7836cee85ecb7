"""Snapshots: the full state of every world in one file, saved atomically, checked before use.

A snapshot is one uncompressed `.npz` (a zip of .npy arrays; numpy reads it without pickle):
`header` (UTF-8 JSON: format, name, created, tick, the batch header of `provenance.py`, a
sha256 over every array, and `randomization`: per world the last seed and spec the state holds,
grouped as in core/randomizations.py) plus the arrays of a `BatchState`. It is written to a
temporary file, fsynced and renamed, so a crash leaves the old file or the new one, never half
of one. Loading reads and checks everything (zip CRCs, digest, header, shapes) before anything
is restored: a truncated, corrupt or foreign file is refused with `Conflict` saying why, and the
batch is untouched. The same bytes are embedded in MCAP recordings as the starting state of a
replay.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import io
import json
import os
import re
import threading
from pathlib import Path
from typing import Any

import numpy as np

from service.core.contract.snapshots import SNAPSHOT_NAME, RandomizationGroup, SnapshotInfo
from service.core.errors import BadCommand, CannotWrite, Conflict, NotFound
from service.core.sim import randomizations
from service.core.sim.batch import Batch, Restorable
from service.core.sim.types import PHYSICS_FIELDS, BatchState
from service.persistence.provenance import mismatch
from service.persistence.storage import describe

# /2 adds the header's `randomization` (per world, the last seed and spec the state holds);
# /1 files load as before, their worlds with none.
FORMAT = "armfleet-snapshot/2"
READABLE = ("armfleet-snapshot/1", FORMAT)
SUFFIX = ".npz"
NAME_PATTERN = SNAPSHOT_NAME  # names become file names: no separators, no hidden files
LATEST = "latest"  # what a clean shutdown saves and `--restore latest` reads
_SCALARS = ("world_ticks", "faults", "targets")


def check_state_support(batch: Batch) -> None:
    """Conflict (409) naming the engine when it cannot save and restore state (yet)."""
    if not isinstance(batch, Restorable):
        raise Conflict(f"the {type(batch).__name__} engine cannot save or restore state")


def check_name(name: str, field: str = "name") -> str:
    """The name, or BadCommand (422) saying what a name may be."""
    if not isinstance(name, str) or not re.fullmatch(NAME_PATTERN, name):
        raise BadCommand(
            field,
            f"a name is 1-64 letters, digits, '.', '_' or '-', not starting with '.' or '-' "
            f"(got {name!r})",
        )
    return name


def _arrays(state: BatchState) -> dict[str, np.ndarray]:
    out = {"tick": np.array(state.tick, dtype=np.int64)}
    out.update({k: np.ascontiguousarray(getattr(state, k)) for k in _SCALARS})
    out.update({f"physics.{k}": np.ascontiguousarray(v) for k, v in state.physics.items()})
    return out


def _digest(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for key in sorted(arrays):
        a = arrays[key]
        h.update(f"{key}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def encode_state(state: BatchState, header: dict[str, Any], name: str = "") -> bytes:
    """The file's bytes: `header` (a `provenance.batch_header`) plus the state, with a digest."""
    arrays = _arrays(state)
    meta = {
        **header,
        "format": FORMAT,
        "name": name,
        "created": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "tick": int(state.tick),
        "sha256": _digest(arrays),
        "randomization": randomizations.groups(state.randomized),
    }
    buf = io.BytesIO()
    head = np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8)
    np.savez(buf, header=head, **arrays)
    return buf.getvalue()


def read_header(data: bytes | Path) -> dict[str, Any]:
    """Only the header (for listings); Conflict if even that cannot be read."""
    try:
        with np.load(data if isinstance(data, Path) else io.BytesIO(data)) as npz:
            return json.loads(npz["header"].tobytes())
    except Exception as exc:
        raise Conflict(f"not a readable snapshot ({type(exc).__name__}: {exc})") from None


def decode_state(data: bytes, current: dict[str, Any] | None = None) -> BatchState:
    """Parse and check a snapshot completely; Conflict (409) saying why when it does not fit.

    `current` is this service's `provenance.batch_header`; when given, the snapshot must have
    been made by a batch it fits (same model, worlds, physics step).
    """
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}  # reading checks every member's CRC
    except Exception as exc:
        raise Conflict(
            f"the snapshot file is truncated or corrupt ({type(exc).__name__}: {exc})"
        ) from None
    try:
        header = json.loads(arrays.pop("header").tobytes())
    except Exception:
        raise Conflict("the snapshot file has no readable header") from None
    if header.get("format") not in READABLE:
        raise Conflict(f"not an {FORMAT} file (format {header.get('format')!r})")
    if _digest(arrays) != header.get("sha256"):
        raise Conflict("the snapshot's arrays do not match its checksum (corrupt file)")
    if current is not None and (why := mismatch(header, current)):
        raise Conflict(f"cannot restore this snapshot: {why}")
    missing = [k for k in ("tick", *_SCALARS) if k not in arrays]
    missing += [f"physics.{f}" for f in PHYSICS_FIELDS if f"physics.{f}" not in arrays]
    if missing:
        raise Conflict(f"the snapshot lacks {', '.join(missing)}")
    nworld = int(arrays["faults"].shape[0])
    try:
        randomized = randomizations.from_groups(header.get("randomization"), nworld)
    except ValueError as exc:
        raise Conflict(f"the snapshot's header is malformed: {exc}") from None
    return BatchState(
        tick=int(arrays["tick"]),
        world_ticks=arrays["world_ticks"],
        faults=arrays["faults"],
        targets=arrays["targets"],
        # the state's fields, and per-world model fields (`MODEL_PREFIX`) where there are any
        physics={k.removeprefix("physics."): v for k, v in arrays.items() if "." in k},
        randomized=randomized,
    )


def write_atomically(path: Path, data: bytes) -> None:
    """Temp file in the same directory, fsync, rename, fsync the directory."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # Unique per thread: two saves of one name at once (a request, the stop) must not share it.
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class SnapshotStore:
    """Snapshots as `<data_dir>/snapshots/<name>.npz`."""

    def __init__(self, data_dir: Path | str):
        self.dir = Path(data_dir).expanduser() / "snapshots"

    def path(self, name: str) -> Path:
        return self.dir / f"{check_name(name)}{SUFFIX}"

    def save(self, name: str, state: BatchState, header: dict[str, Any]) -> SnapshotInfo:
        """Write snapshot `name`; CannotWrite (507) naming the cause, the old file kept."""
        data = encode_state(state, header, name)
        path = self.path(name)
        try:
            write_atomically(path, data)
        except OSError as exc:
            why = f"cannot write snapshot {name!r} to {path}: {describe(exc)}"
            raise CannotWrite(f"{why}; any earlier {name!r} is kept", "name") from None
        return self._info(name, path, read_header(data))

    def load_bytes(self, name: str) -> bytes:
        path = self.path(name)
        try:
            return path.read_bytes()
        except FileNotFoundError:
            raise NotFound(f"no snapshot named {name!r}", "name") from None

    def load(self, name: str, current: dict[str, Any]) -> BatchState:
        """The checked state of snapshot `name`: NotFound (404) or Conflict (409) otherwise."""
        return decode_state(self.load_bytes(name), current)

    def list(self) -> list[SnapshotInfo]:
        """Every readable snapshot, newest first (unreadable files are skipped)."""
        out = []
        for path in self.dir.glob(f"*{SUFFIX}"):
            if path.name.startswith("."):
                continue
            with contextlib.suppress(Conflict, OSError):
                out.append(self._info(path.stem, path, read_header(path)))
        return sorted(out, key=lambda i: (i.created, i.name), reverse=True)

    @staticmethod
    def _info(name: str, path: Path, header: dict[str, Any]) -> SnapshotInfo:
        return SnapshotInfo(
            name=name,
            size_bytes=path.stat().st_size,
            created=str(header.get("created", "")),
            tick=int(header.get("tick", -1)),
            nworld=int(header.get("nworld", -1)),
            model_hash=str(header.get("model_hash", "")),
            format=str(header.get("format", "")),
            randomization=[RandomizationGroup(**g) for g in header.get("randomization") or ()],
        )
