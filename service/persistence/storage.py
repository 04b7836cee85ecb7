"""Files the service writes (recordings, snapshots): failures that name their cause, writes that
cannot hang.

A recording may go to a FIFO or pipe as well as to a file. Opened the ordinary way, a FIFO that
nobody reads blocks `open` forever, and one whose reader stopped draining blocks every write:
a request that starts a recording would never answer, and stopping the service would wait for
good. Here the descriptor is non-blocking: opening a FIFO without a reader fails at once (ENXIO),
and a write that finds no room waits for it at most `stall_s`, then fails naming the stall. On a
regular file non-blocking changes nothing (the disk is waited for as always) and a full disk or a
read-only mount fails the write with its own errno, which `cannot_write` turns into the domain
error the caller gets (`CannotWrite`, 507).
"""

from __future__ import annotations

import errno
import io
import os
import select
import stat
import time
from pathlib import Path

from service.core.errors import CannotWrite

STALL_S = 5.0  # [s] a write that finds no room for this long fails (a reader that stopped)

_HINTS = {
    errno.ENXIO: "no process has the FIFO open for reading",
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is used up",
    errno.EROFS: "the file system is mounted read-only",
}


def describe(exc: BaseException) -> str:
    """The cause in words: the OS's message (plus a hint) for OSError, else type and message."""
    if isinstance(exc, OSError) and exc.strerror:
        hint = _HINTS.get(exc.errno or 0)
        return f"{exc.strerror}" + (f" ({hint})" if hint else "")
    return f"{type(exc).__name__}: {exc}"


def cannot_write(what: str, path: Path, exc: BaseException) -> CannotWrite:
    """The error a caller gets when `what` (e.g. "recording") cannot be written at `path`."""
    return CannotWrite(f"cannot write {what} {path}: {describe(exc)}", "path")


class StalledWrite(TimeoutError):
    """A write found no room for `STALL_S` (a pipe or FIFO whose reader stopped reading)."""


class _NonBlockingFile(io.RawIOBase):
    """A raw, write-only, non-blocking descriptor whose writes wait for room up to `stall_s`."""

    def __init__(self, fd: int, stall_s: float) -> None:
        super().__init__()
        self._fd = fd
        self._stall_s = stall_s
        self.regular = stat.S_ISREG(os.fstat(fd).st_mode)

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def write(self, data: bytes | bytearray | memoryview) -> int:  # type: ignore[override]
        deadline = time.monotonic() + self._stall_s
        while True:
            try:
                return os.write(self._fd, data)
            except BlockingIOError:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise StalledWrite(
                        errno.ETIMEDOUT,
                        f"no data could be written for {self._stall_s:g} s "
                        "(a pipe or FIFO whose reader stopped reading)",
                    ) from None
                select.select([], [self._fd], [], left)

    def close(self) -> None:
        if not self.closed:
            try:
                os.close(self._fd)
            finally:
                super().close()


class GuardedWriter(io.BufferedWriter):
    """A buffered writer on `_NonBlockingFile`; `sync` makes a regular file durable."""

    def sync(self) -> None:
        """Flush, and fsync when it is a regular file (a pipe has nothing to sync)."""
        self.flush()
        raw = self.raw
        if isinstance(raw, _NonBlockingFile) and raw.regular:
            os.fsync(raw.fileno())


def open_for_writing(path: Path, stall_s: float = STALL_S) -> GuardedWriter:
    """Create or truncate `path` (its folder too) for writing; OSError saying why it cannot be.

    Fails at once on a FIFO that no process reads (ENXIO), a read-only or full file system,
    or a folder that cannot be made.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NONBLOCK | os.O_CLOEXEC
    fd = os.open(path, flags, 0o644)
    try:
        return GuardedWriter(_NonBlockingFile(fd, stall_s), buffer_size=1 << 16)
    except BaseException:
        os.close(fd)
        raise
