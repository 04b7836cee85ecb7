"""A WebSocket for threads: a message goes out from the thread that sends it, at once.

The command lanes (lanes.py) send a ROS user's command from the executor thread whose callback
took the message. Through the link's event loop (asyncio) the command first waited for that
loop's thread to be woken and to get the interpreter, which the executor keeps after a
callback to walk its entities again: on a busy 2-core box that hop was milliseconds, the
largest part of what the node added to a round trip that it controls (bench section 8's
trace: ROS message in → command written, 7 ms median at load 50). Here websockets' own
protocol (sans-I/O: the library's handshake, framing, masking, pings and close, not ours)
runs over a blocking socket: `send` frames and writes under a lock in the caller's thread;
one reading thread (`recv`) answers the server's pings under the same lock.
"""

from __future__ import annotations

import contextlib
import socket
import ssl
import threading
from collections.abc import Mapping

from websockets.client import ClientProtocol
from websockets.frames import Opcode
from websockets.http11 import Response
from websockets.protocol import State
from websockets.uri import parse_uri

READ = 1 << 16


class LineClosed(ConnectionError):
    """The socket is closed (by either side) or was lost."""


class ThreadSocket:
    """One client WebSocket: `send` from any thread, `recv` from one reading thread."""

    def __init__(
        self, url: str, headers: Mapping[str, str], max_size: int, timeout: float = 10.0
    ) -> None:
        """Connect and shake hands (OSError, TimeoutError or websockets' InvalidHandshake
        when the server is not there or refuses)."""
        uri = parse_uri(url)
        self._protocol = ClientProtocol(uri, max_size=max_size)
        sock = socket.create_connection((uri.host, uri.port), timeout=timeout)
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            if uri.secure:
                context = ssl.create_default_context()
                sock = context.wrap_socket(sock, server_hostname=uri.host)
        except BaseException:
            sock.close()
            raise
        self._sock = sock
        self._lock = threading.Lock()
        self._parts: list[bytes] = []  # a fragmented message's frames so far
        self._text = False
        self._ready: list[str | bytes] = []  # messages that came with the handshake's reply
        try:
            self._handshake(headers)
        except BaseException:
            sock.close()
            raise
        sock.settimeout(None)

    def _handshake(self, headers: Mapping[str, str]) -> None:
        request = self._protocol.connect()
        for name, value in headers.items():
            request.headers[name] = value
        self._protocol.send_request(request)
        self._flush()
        while self._protocol.state is State.CONNECTING:
            self._feed(self._sock.recv(READ))
            for event in self._protocol.events_received():
                if not isinstance(event, Response):
                    self._take(event)
            if self._protocol.handshake_exc is not None:
                raise self._protocol.handshake_exc

    def send(self, text: str) -> None:
        """Send a text message now, from this thread (LineClosed once the socket is not open)."""
        with self._lock:
            if self._protocol.state is not State.OPEN:
                raise LineClosed("the socket is closed")
            self._protocol.send_text(text.encode())
            self._flush()

    def recv(self) -> str | bytes | None:
        """The next message (text as str); None once the socket is closed or lost. One thread."""
        while not self._ready:
            try:
                data = self._sock.recv(READ)
            except OSError:
                data = b""
            with self._lock:
                self._feed(data)
                for event in self._protocol.events_received():
                    self._take(event)
                try:
                    self._flush()  # pongs, the close's reply
                except LineClosed:
                    data = b""
            if (not data or self._protocol.state is State.CLOSED) and not self._ready:
                return None
        return self._ready.pop(0)

    def close(self) -> None:
        """Say goodbye if still open, and end the connection (a blocked `recv` returns None)."""
        with self._lock, contextlib.suppress(LineClosed):
            if self._protocol.state is State.OPEN:
                self._protocol.send_close()
                self._flush()
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()

    # -- inside ---------------------------------------------------------------------------

    def _feed(self, data: bytes) -> None:
        if data:
            self._protocol.receive_data(data)
        else:
            self._protocol.receive_eof()

    def _take(self, frame: object) -> None:
        """A data frame in: a message once its last fragment came (control frames are the
        protocol's: it answers pings and closes)."""
        opcode = getattr(frame, "opcode", None)
        if opcode in (Opcode.TEXT, Opcode.BINARY):
            self._parts, self._text = [], opcode is Opcode.TEXT
        elif opcode is not Opcode.CONT:
            return
        self._parts.append(frame.data)  # type: ignore[attr-defined]
        if frame.fin:  # type: ignore[attr-defined]
            data = b"".join(self._parts)
            self._parts = []
            self._ready.append(data.decode() if self._text else data)

    def _flush(self) -> None:
        """Write what the protocol has to send (the lock held, or the handshake)."""
        for chunk in self._protocol.data_to_send():
            try:
                if chunk:
                    self._sock.sendall(chunk)
                else:  # the protocol's end of stream
                    self._sock.shutdown(socket.SHUT_WR)
            except OSError as exc:
                raise LineClosed(str(exc)) from exc
