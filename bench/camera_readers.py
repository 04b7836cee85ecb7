"""Clients of the cameras' WebSocket stream for section 30 (bench/cameras_gpu.py): `k` processes,
each reading its share of the worlds' pictures, raw, and counting whole messages and bytes.

Why processes: a reader of gigabytes a second must not share a GIL with the others or with the
bench. The client library is aiohttp (its frame reader is compiled: about twice the websockets
sync client's throughput per connection on loopback); ARMFLEET_BENCH_CLIENT=websockets uses the
websockets sync client instead.
"""

from __future__ import annotations

import contextlib
import json
import os
from typing import Any


def _first_message(msg: bytes, worlds: list[int]) -> dict[str, Any]:
    """What the first message of a client says: its worlds, image sizes, wholeness."""
    hlen = int.from_bytes(msg[4:8], "little")
    head = json.loads(msg[8 : 8 + hlen])
    sizes = head["sizes"]
    return {
        "every_world": head["worlds"] == worlds,
        "image_bytes": sorted(set(sizes)),
        "message_bytes": len(msg),
        "whole": len(msg) == 8 + hlen + sum(sizes),
    }


def _read(url: str, worlds: list[int], counts: Any, first: Any, stop: Any) -> None:
    """One camera-stream client, in a process of its own: counts whole messages and bytes
    into `counts`, checks the first message (its summary or error goes to `first`)."""
    try:
        if client_name().startswith("websockets "):
            _read_websockets(url, worlds, counts, first, stop)
        else:
            import asyncio

            asyncio.run(_read_aiohttp(url, worlds, counts, first, stop))
    except Exception as exc:
        first.put({"error": f"{type(exc).__name__}: {exc}"})


def client_name() -> str:
    """The stream clients' library (ARMFLEET_BENCH_CLIENT), with its version."""
    from importlib.metadata import version

    name = os.environ.get("ARMFLEET_BENCH_CLIENT", "aiohttp")
    return f"{name} {version(name)}"


def _count(msg: bytes, worlds: list[int], counts: Any, first: Any) -> None:
    if first.empty():
        first.put(_first_message(msg, worlds))
    with counts.get_lock():
        counts[0] += 1
        counts[1] += len(msg)


def _read_websockets(url: str, worlds: list[int], counts: Any, first: Any, stop: Any) -> None:
    from websockets.sync.client import connect

    with connect(url, max_size=None, compression=None, open_timeout=60) as ws:
        while not stop.is_set():
            with contextlib.suppress(TimeoutError):
                _count(ws.recv(timeout=5), worlds, counts, first)


async def _read_aiohttp(url: str, worlds: list[int], counts: Any, first: Any, stop: Any) -> None:
    import aiohttp

    timeout = aiohttp.ClientTimeout(total=None, connect=60)
    async with (
        aiohttp.ClientSession(timeout=timeout) as session,
        session.ws_connect(url, max_msg_size=0, compress=0) as ws,
    ):
        while not stop.is_set():
            try:
                msg = await ws.receive(timeout=5)
            except TimeoutError:
                continue
            if msg.type != aiohttp.WSMsgType.BINARY:
                raise RuntimeError(f"the stream ended: {msg.type.name} {msg.data!r}")
            _count(msg.data, worlds, counts, first)


class Readers:
    """`k` client processes, each streaming its share of the worlds 0..n-1."""

    def __init__(self, ws_url: str, n: int, k: int, camera: str, rate: float) -> None:
        import multiprocessing as mp

        spawn = mp.get_context("spawn")
        self.stop = spawn.Event()
        self.k, self.n = k, n
        self.counts = [spawn.Array("q", 2) for _ in range(k)]  # messages, bytes
        self.firsts = [spawn.Queue() for _ in range(k)]
        self.procs = []
        self.shares = [(i + 1) * n // k - i * n // k for i in range(k)]  # worlds per client
        for i in range(k):
            lo, hi = i * n // k, (i + 1) * n // k - 1
            q = f"camera={camera}&worlds={lo}-{hi}&rate={rate:g}&image=rgb&format=raw"
            args = (f"{ws_url}/v1/ws/cameras?{q}", list(range(lo, hi + 1)))
            args += (self.counts[i], self.firsts[i], self.stop)
            self.procs.append(spawn.Process(target=_read, args=args, daemon=True))
        for proc in self.procs:
            proc.start()

    def frames(self) -> float:
        """Pictures of every world delivered so far (each client's messages x its share)."""
        return sum(c[0] * w for c, w in zip(self.counts, self.shares, strict=True)) / self.n

    def messages(self) -> int:
        return sum(int(c[0]) for c in self.counts)

    def close(self) -> dict[str, Any]:
        self.stop.set()
        for proc in self.procs:
            proc.join(timeout=30)
            if proc.is_alive():
                proc.kill()
        firsts = [q.get(timeout=5) if not q.empty() else {} for q in self.firsts]
        return {
            "clients": self.k,
            "messages": self.messages(),
            "bytes": sum(int(c[1]) for c in self.counts),
            "first": firsts[0],
            "errors": [f["error"] for f in firsts if "error" in f],
            "every_world": all(f.get("every_world") for f in firsts),
            "whole_messages": all(f.get("whole") for f in firsts),
            "image_bytes": sorted({b for f in firsts for b in f.get("image_bytes", [])}),
        }
