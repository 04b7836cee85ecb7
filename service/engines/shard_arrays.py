"""Large replies of a shard worker (snapshots, states) through shared memory, not the pipe.

A snapshot of 16,384 worlds is 12 MB. Through the worker's pipe it cost the loop's thread
about 24 ms (the pipe moves about 0.5 GB/s once pickled and read back in chunks), ten times a
second even with nobody looking; through a shared block it is one copy in and one copy out.

The worker owns one block per pipe and writes a reply's array bytes into it (pickle protocol 5
hands them out of band); the pipe carries the rest of the pickle and where each array lies.
The parent copies the bytes out before it sends its next request, and requests on one pipe
come one at a time from one thread (the loop's), so the block is never written while read.
"""

from __future__ import annotations

import io
import pickle
from multiprocessing import shared_memory
from multiprocessing.connection import Connection
from typing import Any

import numpy as np


class _Contiguous(pickle.Pickler):
    """Pickles every array out of band: a strided one (a column of the engine's packed host
    buffer) as a contiguous copy, which pickle would otherwise copy in band, byte by byte."""

    def reducer_override(self, obj: Any) -> Any:
        if isinstance(obj, np.ndarray) and not obj.flags.c_contiguous and not obj.dtype.hasobject:
            return np.ascontiguousarray, (np.ascontiguousarray(obj),)
        return NotImplemented


class ArraySender:
    """The worker's side: a shared block that grows to the largest reply sent so far."""

    def __init__(self) -> None:
        self._block: shared_memory.SharedMemory | None = None

    def send(self, conn: Connection, obj: Any) -> None:
        buffers: list[pickle.PickleBuffer] = []
        out = io.BytesIO()
        _Contiguous(out, protocol=5, buffer_callback=buffers.append).dump(obj)
        head = out.getvalue()
        views = [b.raw() for b in buffers]
        block = self._room(sum(v.nbytes for v in views))
        places, at = [], 0
        for view in views:
            block.buf[at : at + view.nbytes] = view
            places.append((at, view.nbytes))
            at += view.nbytes
        conn.send((head, block.name if places else "", places))

    def _room(self, size: int) -> shared_memory.SharedMemory:
        if self._block is None or self._block.size < size:
            self.close()
            self._block = shared_memory.SharedMemory(create=True, size=max(size, 1))
        return self._block

    def close(self) -> None:
        if self._block is not None:
            self._block.close()
            self._block.unlink()
            self._block = None


class ArrayReceiver:
    """The parent's side: the worker's block, opened once per name (a grown block is new)."""

    def __init__(self) -> None:
        self._block: shared_memory.SharedMemory | None = None

    def recv(self, conn: Connection) -> Any:
        head, name, places = conn.recv()
        if not places:
            return pickle.loads(head)
        if self._block is None or self._block.name != name.lstrip("/"):
            self.close()
            # the worker owns and unlinks it; opening it registers the name again with the
            # resource tracker the worker shares with us (a set: no change), which unlinks it
            # when the service ends only if a killed worker could not
            self._block = shared_memory.SharedMemory(name=name)
        buf = self._block.buf
        arrays = [bytearray(buf[at : at + size]) for at, size in places]  # copies, writable
        return pickle.loads(head, buffers=arrays)

    def close(self) -> None:
        if self._block is not None:
            self._block.close()
            self._block = None
