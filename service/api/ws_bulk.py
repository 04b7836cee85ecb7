"""BulkSocket: a WebSocket taken over after its handshake, for messages of many megabytes.

A camera stream of 16,384 worlds sends a 201 MB message thirty times a second. Through the ASGI
`send`, each message was copied three times while holding the interpreter (joined into bytes,
framed by websockets into a buffer, buffered by the event loop's transport), about 25 ms per
copy, and written by the one event-loop thread: one process could not send more than a few such
pictures a second, and the simulation loop and the renderer waited for the interpreter behind
those copies. Here a message's frame header, its own header and its pixels are handed to
`sendmsg` as one gather list by a thread of the socket's own, whose system calls release the
interpreter: the kernel's copy into the socket is the only one, and sockets are written in
parallel.

How, on uvicorn's websockets (sans-io) protocol, which did the handshake:
- the transport's protocol is swapped for `_Reader`: what the client sends (pings, close, text)
  is parsed by a websockets `Protocol` of ours (the library's, not a re-implementation) that
  says what to answer; uvicorn's protocol is told only of the connection's loss, so its
  bookkeeping and its shutdown go on;
- uvicorn's keepalive is stopped and its protocol marked as having sent its close, so that it
  never writes to this socket again (its shutdown then only closes the transport);
- every frame (our data, pongs, the close) is written in order by the socket's writer thread,
  through a duplicate of the socket's descriptor.

The same holds, ten times smaller, for binary state frames of /v1/ws (10 MB a frame at 65,536
worlds, 30 a second): service/api/ws.py takes those sockets over too, and their acks (text)
go through the same writer, in order.

Where the server is something else (a test client, another ASGI server), `take_over` returns
None and `AsgiSocket` makes the same calls on the ASGI socket (`link` picks). Data frames go
out uncompressed, which RFC 7692 allows on a socket that negotiated permessage-deflate (RSV1
clear).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import os
import queue
import select
import socket
import struct
import threading
from collections.abc import Sequence
from typing import Any

from starlette.types import ASGIApp, Receive, Scope, Send
from starlette.websockets import WebSocket, WebSocketDisconnect
from websockets.frames import Opcode
from websockets.protocol import Protocol, Side, State

SCOPE_KEY = "armfleet.ws_owner"  # the ASGI server's protocol object, where it is uvicorn's
MAX_INCOMING = 1 << 16  # what a bulk socket's client may send in one message (pull requests)
FLUSH_S = 5.0  # at most this long for the writer to finish what it holds when a stream ends
_POLL_MS = 500  # a writer waiting for room looks this often whether it was told to stop

Buffer = bytes | bytearray | memoryview


class RememberOwner:
    """ASGI middleware, outermost: keeps the server's own `send` owner in the scope of each
    WebSocket, where a route can take the socket over (the app's inner middleware wrap `send`
    in closures, so the route's `WebSocket` no longer sees it)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "websocket":
            scope[SCOPE_KEY] = getattr(send, "__self__", None)
        await self.app(scope, receive, send)


def take_over(scope: Scope, max_incoming: int | None = MAX_INCOMING) -> BulkSocket | None:
    """The accepted WebSocket of `scope` as a BulkSocket, or None where the server is not
    uvicorn's websockets sans-io protocol (or the connection is already closing).
    `max_incoming`: the longest message the client may send (None: the server's own limit).
    Call it right after the accept, with no await between: what the client sends after that
    reaches the BulkSocket alone."""
    owner = scope.get(SCOPE_KEY)
    try:
        from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol
    except ImportError:  # pragma: no cover - uvicorn without websockets
        return None
    if not isinstance(owner, WebSocketsSansIOProtocol) or not owner.handshake_complete:
        return None
    transport = owner.transport
    raw = transport.get_extra_info("socket")
    if raw is None or transport.is_closing() or owner.close_sent:
        return None
    limit = owner.conn.max_message_size if max_incoming is None else max_incoming
    return BulkSocket(owner, raw.fileno(), limit)


def link(ws: WebSocket, max_incoming: int | None = MAX_INCOMING) -> BulkSocket | AsgiSocket:
    """The accepted `ws` taken over where the server allows (`take_over`), else its ASGI
    stand-in; both make the same calls."""
    return take_over(ws.scope, max_incoming) or AsgiSocket(ws)


def frame_header(length: int, opcode: int = Opcode.BINARY.value) -> bytes:
    """The header of one unfragmented, unmasked server frame of `length` payload bytes
    (RFC 6455, section 5.2)."""
    first = 0x80 | opcode
    if length < 126:
        return struct.pack("!BB", first, length)
    if length < 1 << 16:
        return struct.pack("!BBH", first, 126, length)
    return struct.pack("!BBQ", first, 127, length)


class Closed(ConnectionError):
    """The client closed the socket, or it broke, before a message could be sent."""


class BulkSocket:
    """One taken-over WebSocket: `send` (whole binary messages as parts), `send_texts`,
    `receive` (the client's messages), `close`; `finish` once done. Used from the event
    loop's thread; only the writer thread touches the socket."""

    direct = True  # written by a thread of its own (metrics count these sockets)

    def __init__(self, owner: Any, fd: int, max_incoming: int | None = MAX_INCOMING) -> None:
        self._owner = owner
        self._aio = asyncio.get_running_loop()
        self._ws = Protocol(Side.SERVER, state=State.OPEN, max_size=max_incoming)
        self._ws.extensions = list(owner.conn.extensions)  # to read compressed client frames
        self._sock = socket.socket(fileno=os.dup(fd))  # same connection, our own descriptor
        self._sock.setblocking(False)
        self._texts: asyncio.Queue[str | bytes | None] = asyncio.Queue()
        for message in _pending(owner):  # read by uvicorn before the take-over, never taken
            self._texts.put_nowait(message)
        self._msg: list[bytes] | None = None  # a fragmented message being read
        self._msg_text = False  # ... and whether it is text
        self._out: queue.SimpleQueue[tuple[list[Buffer], concurrent.futures.Future] | None]
        self._out = queue.SimpleQueue()
        self._stop = threading.Event()  # the writer gives up on what it is writing
        self.gone = asyncio.Event()  # the client closed, or the connection broke
        owner.stop_keepalive()
        owner.close_sent = True  # uvicorn writes nothing more here, not even on shutdown
        self._writer = threading.Thread(target=self._write_all, name="armfleet-ws-bulk")
        self._writer.daemon = True
        self._writer.start()
        owner.transport.set_protocol(_Reader(self))

    # -- from the event loop ---------------------------------------------------------------

    async def send(self, parts: Sequence[Buffer]) -> None:
        """Send one binary message made of `parts` (no copy is made: they must not change
        until this returns); Closed if the client is gone."""
        if self._ws.state is not State.OPEN or self.gone.is_set():
            raise Closed("the client closed the socket")
        size = sum(memoryview(p).nbytes for p in parts)
        await self._sent(self._write([frame_header(size), *parts]))

    async def send_texts(self, texts: Sequence[bytes]) -> None:
        """Send each of `texts` (UTF-8) as a text message, in one write; Closed if the client
        is gone."""
        if self._ws.state is not State.OPEN or self.gone.is_set():
            raise Closed("the client closed the socket")
        text = Opcode.TEXT.value
        await self._sent(self._write([b for t in texts for b in (frame_header(len(t), text), t)]))

    async def _sent(self, done: concurrent.futures.Future) -> None:
        try:
            await asyncio.wrap_future(done)
        except OSError as exc:
            raise Closed(str(exc)) from exc

    async def receive(self) -> str | bytes | None:
        """The client's next message (text as str, binary as bytes); None once the client
        has gone."""
        if self.gone.is_set() and self._texts.empty():
            return None
        return await self._texts.get()

    async def close(self, code: int = 1000, reason: str = "") -> None:
        """Start the closing handshake (once); the client's answer is not waited for."""
        if self._ws.state is State.OPEN:
            self._ws.send_close(code, reason)
            self._flush()
        self._left()

    async def finish(self) -> None:
        """Stop the writer once what it holds is written, the close frame last (a client that
        left makes those writes fail at once; one that stopped reading is given up on after
        FLUSH_S), and drop our descriptor; uvicorn closes the transport when the route
        returns."""
        self._out.put(None)
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(asyncio.shield(self._joined()), FLUSH_S)
        self._stop.set()
        await self._joined()
        self._sock.close()

    async def _joined(self) -> None:
        await asyncio.to_thread(self._writer.join)

    # -- what the client sends (event loop) -------------------------------------------------

    def _received(self, data: bytes) -> None:
        self._ws.receive_data(data)
        for frame in self._ws.events_received():
            if frame.opcode in (Opcode.TEXT, Opcode.BINARY):
                self._msg, self._msg_text = [], frame.opcode is Opcode.TEXT
            if frame.opcode in (Opcode.TEXT, Opcode.BINARY, Opcode.CONT) and self._msg is not None:
                self._msg.append(frame.data)
                if frame.fin:
                    whole = b"".join(self._msg)
                    self._texts.put_nowait(
                        whole.decode("utf-8", "replace") if self._msg_text else whole
                    )
                    self._msg = None
        self._flush()  # pongs, the close answer, a protocol error's close
        if self._ws.state is not State.OPEN:
            self._left()

    def _flush(self) -> None:
        """What our websockets Protocol has to say, queued behind the messages in flight."""
        out = [b for b in self._ws.data_to_send() if b]  # b"" only marks the end of writing
        if out:
            self._write(out)

    def _left(self) -> None:
        if not self.gone.is_set():
            self.gone.set()
            self._texts.put_nowait(None)

    def _write(self, parts: list[Buffer]) -> concurrent.futures.Future:
        done: concurrent.futures.Future = concurrent.futures.Future()
        self._out.put((parts, done))
        return done

    # -- the writer thread -----------------------------------------------------------------

    def _write_all(self) -> None:
        broken: OSError | None = None
        while (item := self._out.get()) is not None:
            parts, done = item
            # A send whose awaiting task was cancelled (the socket's task ended) cancelled its
            # future: its buffers are the caller's again, so the message is not written, and
            # setting a result on it would raise InvalidStateError and end this thread.
            if not done.set_running_or_notify_cancel():
                continue
            if broken is None:
                try:
                    self._send_parts(parts)
                except OSError as exc:
                    broken = exc
                    self._aio.call_soon_threadsafe(self._left)
            if broken is None:
                done.set_result(None)
            else:
                done.set_exception(broken)

    def _send_parts(self, parts: list[Buffer]) -> None:
        """All of `parts`, in order, with as few system calls as the socket's room allows."""
        views = [m for p in parts if (m := memoryview(p).cast("B")).nbytes]
        poll = select.poll()
        poll.register(self._sock.fileno(), select.POLLOUT)
        while views:
            if self._stop.is_set():
                raise ConnectionAbortedError("the stream stopped before the message was sent")
            try:
                sent = self._sock.sendmsg(views)
            except BlockingIOError:
                sent = 0
            while sent and views:
                if sent >= views[0].nbytes:
                    sent -= views.pop(0).nbytes
                else:
                    views[0], sent = views[0][sent:], 0
            if views:
                poll.poll(_POLL_MS)  # room in the socket, or time to look at `_stop` again


def _pending(owner: Any) -> list[str | bytes]:
    """Messages uvicorn read and queued for the ASGI app before the take-over (none when the
    take-over follows the accept at once, as `take_over` asks; kept for safety)."""
    out: list[str | bytes] = []
    queue_ = getattr(owner, "queue", None)
    while queue_ is not None and not queue_.empty():
        message = queue_.get_nowait()
        if message.get("type") == "websocket.receive":
            out.append(message["text"] if message.get("text") is not None else message["bytes"])
    return out


class AsgiSocket:
    """BulkSocket's calls on the ASGI socket, where the server's cannot be taken over: each
    message is joined into bytes and sent through the server (copies that streams of many
    megabytes a second cannot afford, but every ASGI server can do it)."""

    direct = False

    def __init__(self, ws: WebSocket) -> None:
        self._ws = ws

    async def send(self, parts: Sequence[Buffer]) -> None:
        await self._ws.send_bytes(parts[0] if len(parts) == 1 else b"".join(parts))  # type: ignore[arg-type]

    async def send_texts(self, texts: Sequence[bytes]) -> None:
        for text in texts:
            await self._ws.send_text(text.decode())

    async def receive(self) -> str | bytes | None:
        try:
            message = await self._ws.receive()
        except (WebSocketDisconnect, RuntimeError):
            return None
        if message["type"] == "websocket.disconnect":
            return None
        return message["text"] if message.get("text") is not None else message.get("bytes", b"")

    async def close(self, code: int = 1000, reason: str = "") -> None:
        with contextlib.suppress(Exception):
            await self._ws.close(code=code, reason=reason)

    async def finish(self) -> None:
        pass


class _Reader(asyncio.Protocol):
    """The transport's protocol once taken over: bytes in go to the BulkSocket; the loss of
    the connection goes to uvicorn's protocol as well (its own bookkeeping)."""

    def __init__(self, bulk: BulkSocket) -> None:
        self._bulk = bulk

    def data_received(self, data: bytes) -> None:
        self._bulk._received(data)

    def eof_received(self) -> bool | None:
        self._bulk._left()
        return None

    def connection_lost(self, exc: Exception | None) -> None:
        self._bulk._left()
        self._bulk._owner.connection_lost(exc)

    def pause_writing(self) -> None:  # nothing is written through the transport any more
        pass

    def resume_writing(self) -> None:
        pass
