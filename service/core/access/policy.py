"""Who may read and who may command, and how much: the one access policy of every surface.

Bound to loopback the service trusts its machine (no token needed); bound anywhere else it needs
a token unless the operator says `--insecure`. With a token, every write (HTTP POST/PUT/…,
WebSocket commands, rosbridge/Foxglove publishes) must present it; reads stay open unless
`token_reads`. Browsers cannot set headers on WebSockets, so a socket may present the token as a
`?token=` query or as a subprotocol `armfleet.token.<TOKEN>`. A browser socket from a foreign
Origin may watch but never command (a page on another site must not drive the arms of a
colleague who happens to have the service open). Each connection's commands go through a token
bucket (`RateLimiter`), and `ClientSlots` caps how many clients are served at once, so that one
client cannot starve the loop or the others.

Leases (service.core.access.leases) add tokens of their own: a lease token may command its lease's
worlds on every surface (the check per world is `callers.Gate`, run by Control); over HTTP it
may write only the command routes and its own lease (`LEASE_WRITES`), never the service's files.
The resolved `callers.Caller` of a request is kept in its scope's state (`caller`).

HTTP is checked by `AccessMiddleware` (so routes added later are covered without opting in);
WebSocket surfaces call `check_ws(...)` for a `Grant`, hold a `ClientSlots` slot while connected,
and feed each command to their own `RateLimiter`.
"""

from __future__ import annotations

import hmac
import ipaddress
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlsplit

from starlette.responses import JSONResponse
from starlette.routing import Match
from starlette.types import ASGIApp, Receive, Scope, Send

from service.core.access.callers import OPEN, Caller, identify
from service.core.access.leases import LeaseBook
from service.core.access.settings import AccessSettings
from service.core.errors import BadToken

TOKEN_SUBPROTOCOL = "armfleet.token."  # + the token: how a browser socket presents it
APP_SUBPROTOCOL = "armfleet"  # offered beside the token one; the server answers with this
CLOSE_POLICY = 1008  # WebSocket close: policy violation (bad token, over the command rate)
CLOSE_TRY_AGAIN = 1013  # WebSocket close: try again later (client cap reached)
# Probes, the API description and the browser page's own files (no data in them) stay readable
# even with `token_reads`; the page then reads the token from its URL for its requests.
OPEN_PATHS = frozenset(
    {"/", "/healthz", "/readyz", "/docs", "/openapi.json", "/docs/oauth2-redirect"}
)
OPEN_PREFIXES = ("/web/",)
_READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
# What a lease token may write over HTTP (its worlds are then Control's check); the rest
# (snapshots, recordings, asking for leases) needs the administrator's token.
LEASE_WRITES = ("/v1/worlds/", "/v1/targets", "/v1/reset", "/v1/trajectories", "/v1/sim/")
_API_WRITES = frozenset({"POST", "PUT", "PATCH", "DELETE"})  # others: 405 from the routes
LEASE_OWN = "/v1/leases/"  # + its own id: renew, release


class AccessError(Exception):
    """Refused: `status` is the HTTP status (401 no/wrong token, 403 foreign origin)."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


# -- start-up ---------------------------------------------------------------------------------


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 and `localhost`; anything else (0.0.0.0 included) is reachable."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:  # a host name: it may resolve to anything
        return False


def check_bind(host: str, settings: AccessSettings) -> None:
    """Refuse to serve a non-loopback address without a token, unless told `insecure`."""
    if is_loopback(host) or settings.token or settings.insecure:
        return
    raise ValueError(
        f"refusing to bind {host}: anyone who can reach it could drive every arm. "
        "Give --token (or ARMFLEET_TOKEN), or --insecure to serve it open anyway."
    )


# -- checks -----------------------------------------------------------------------------------


def token_matches(settings: AccessSettings, presented: str | None) -> bool:
    """True when no token is configured, or `presented` is it (compared in constant time)."""
    if not settings.token:
        return True
    if presented is None:
        return False
    return hmac.compare_digest(presented.encode(), settings.token.encode())


def bearer(headers: Mapping[str, str]) -> str | None:
    """The token of an `Authorization: Bearer <token>` header, if any."""
    value = headers.get("authorization", "")
    scheme, _, token = value.partition(" ")
    return token.strip() if scheme.lower() == "bearer" and token.strip() else None


def origin_allowed(settings: AccessSettings, headers: Mapping[str, str]) -> bool:
    """No Origin (not a browser), the same host as the request, or one the operator listed."""
    origin = headers.get("origin")
    if origin is None:
        return True
    if origin in settings.allow_origins:
        return True
    host = headers.get("host")
    return host is not None and urlsplit(origin).netloc.lower() == host.lower()


def is_open(path: str) -> bool:
    """Paths anyone may read whatever the settings (OPEN_PATHS, OPEN_PREFIXES)."""
    return path in OPEN_PATHS or path.startswith(OPEN_PREFIXES)


def check_http(
    settings: AccessSettings,
    method: str,
    path: str,
    headers: Mapping[str, str],
    book: LeaseBook | None = None,
) -> Caller | None:
    """The request's caller (None: an open path, or a read presenting no valid token); raise
    AccessError unless this request may go on (see the module docstring)."""
    if is_open(path):
        return None
    write = method.upper() not in _READ_METHODS
    presented = bearer(headers)
    try:
        caller: Caller | None = identify(settings, book, presented)
    except BadToken as exc:
        if write or settings.token_reads:
            what = "writes" if write else "reads"
            hint = "" if presented else ": send `Authorization: Bearer <token>`"
            raise AccessError(401, f"{what}: {exc.detail}{hint}") from None
        caller = None
    lease_write = method.upper() in _API_WRITES and caller is not None and caller.kind == "lease"
    if lease_write and not _lease_writes(caller, path):  # type: ignore[arg-type]
        raise AccessError(403, f"{path} needs the administrator's token, not a lease's")
    if write and not origin_allowed(settings, headers):
        raise AccessError(403, f"origin {headers.get('origin')!r} may not command this service")
    return caller


def _lease_writes(caller: Caller, path: str) -> bool:
    if path.startswith(LEASE_WRITES):
        return True
    own = f"{LEASE_OWN}{caller.lease_id}"
    return path == own or path.startswith(f"{own}/")


@dataclass(frozen=True)
class Grant:
    """What one WebSocket may do, decided once at its handshake.

    read: may subscribe at all (False only with `token_reads` and no valid token)
    command: may send commands / publish
    reason: why `command` (or `read`) is refused, for the error frames; "" when allowed
    subprotocol: the subprotocol to accept with (the client offered one), or None
    caller: who commands through it (its worlds are checked per command by Control)
    """

    read: bool
    command: bool
    reason: str
    subprotocol: str | None
    caller: Caller = OPEN


def check_ws(
    settings: AccessSettings,
    headers: Mapping[str, str],
    query: Mapping[str, str] | str = "",
    subprotocols: Sequence[str] = (),
    book: LeaseBook | None = None,
) -> Grant:
    """The Grant of a WebSocket handshake; any WebSocket server can call this.

    headers: the handshake's headers with lower-case names; query: the URL's query (a mapping or
    the raw string); subprotocols: what the client offered, in order; book: the service's
    leases (a lease token commands its worlds).
    """
    if isinstance(query, str):
        query = {k: v[-1] for k, v in parse_qs(query).items()}
    presented = bearer(headers) or query.get("token")
    reply_protocol = None
    for proto in subprotocols:
        if proto.startswith(TOKEN_SUBPROTOCOL):
            presented = presented or proto[len(TOKEN_SUBPROTOCOL) :]
            reply_protocol = reply_protocol or proto
        elif proto == APP_SUBPROTOCOL:
            reply_protocol = APP_SUBPROTOCOL
    try:
        caller = identify(settings, book, presented)
    except BadToken as exc:
        how = "(?token=, Authorization: Bearer, or subprotocol)"
        why = f"commands need a token {how}: {exc.detail}"
        return Grant(not settings.token_reads, False, why, reply_protocol)
    if not origin_allowed(settings, headers):
        why = f"origin {headers.get('origin')!r} may watch but not command this service"
        return Grant(True, False, why, reply_protocol, caller)
    return Grant(True, True, "", reply_protocol, caller)


def check_websocket(settings: AccessSettings, ws: Any, book: LeaseBook | None = None) -> Grant:
    """check_ws for a Starlette/FastAPI WebSocket (headers, query string, offered subprotocols)."""
    headers = {k.lower(): v for k, v in ws.headers.items()}
    return check_ws(settings, headers, ws.url.query, ws.scope.get("subprotocols", ()), book)


# -- rates and slots --------------------------------------------------------------------------


class RateLimiter:
    """A token bucket for one connection's commands: `rate` per second, bursts of `burst`.

    `take()` answers "ok", "refuse" (send an error frame, keep the socket) or "close" (the client
    went on sending at least `burst` more commands while refused: close with 1008).
    """

    def __init__(self, rate: float, burst: int | None = None) -> None:
        self.rate = float(rate)
        self.burst = int(burst if burst is not None else max(1, round(rate)))
        self._tokens = float(self.burst)
        self._last: float | None = None
        self._refused_in_a_row = 0

    def take(self, now: float | None = None) -> str:
        now = time.monotonic() if now is None else now
        if self._last is not None:
            gained = max(0.0, now - self._last) * self.rate
            self._tokens = min(float(self.burst), self._tokens + gained)
        self._last = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            self._refused_in_a_row = 0
            return "ok"
        self._refused_in_a_row += 1
        return "close" if self._refused_in_a_row > self.burst else "refuse"

    @property
    def detail(self) -> str:
        return f"rate: over {self.rate:g} commands/s (bursts of {self.burst}); slow down"


class ClientSlots:
    """At most `limit` clients at once (0: no limit), shared by every surface of one service."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.active = 0

    def acquire(self) -> bool:
        """Take a slot; False when full (refuse the client: 503 or close 1013)."""
        if self.limit and self.active >= self.limit:
            return False
        self.active += 1
        return True

    def release(self) -> None:
        self.active = max(0, self.active - 1)


# -- the HTTP side ----------------------------------------------------------------------------


class AccessMiddleware:
    """Token and origin checks for every HTTP route; client slots for HTTP and WebSockets.

    WebSocket handshakes only take a slot here (refused with close 1013 when full, or 1008
    when reads need a token the client lacks); what a socket may command is the surface's call
    through `check_websocket`.
    """

    def __init__(
        self,
        app: ASGIApp,
        settings: AccessSettings,
        slots: ClientSlots,
        leases: Callable[[], LeaseBook | None] = lambda: None,
    ) -> None:
        self.app = app
        self.settings = settings
        self.slots = slots
        self.leases = leases  # the service's LeaseBook once it runs

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            await self._http(scope, receive, send)
        elif scope["type"] == "websocket":
            await self._websocket(scope, receive, send)
        else:
            await self.app(scope, receive, send)

    async def _http(self, scope: Scope, receive: Receive, send: Send) -> None:
        headers = _headers(scope)
        try:
            method, path = scope["method"], scope["path"]
            caller = check_http(self.settings, method, path, headers, self.leases())
            scope.setdefault("state", {})["caller"] = caller
        except AccessError as exc:
            if not _routed(scope):  # no route takes it: the router's 404 / 405 says more
                return await self.app(scope, receive, send)
            extra = {"WWW-Authenticate": "Bearer"} if exc.status == 401 else None
            reply = JSONResponse({"detail": exc.detail}, status_code=exc.status, headers=extra)
            return await reply(scope, receive, send)
        if is_open(scope["path"]):  # probes and page files: cheap, never refused for load
            return await self.app(scope, receive, send)
        if not self.slots.acquire():
            reply = JSONResponse(
                {"detail": f"over the limit of {self.slots.limit} clients at once; retry"},
                status_code=503,
                headers={"Retry-After": "1"},
            )
            return await reply(scope, receive, send)
        try:
            await self.app(scope, receive, send)
        finally:
            self.slots.release()

    async def _websocket(self, scope: Scope, receive: Receive, send: Send) -> None:
        query = scope.get("query_string", b"").decode("latin-1")
        grant = check_ws(
            self.settings, _headers(scope), query, scope.get("subprotocols", ()), self.leases()
        )
        if not grant.read:
            return await _close_handshake(receive, send, CLOSE_POLICY, grant.reason)
        if not self.slots.acquire():
            why = f"over the limit of {self.slots.limit} clients at once; retry"
            return await _close_handshake(receive, send, CLOSE_TRY_AGAIN, why)
        try:
            await self.app(scope, receive, send)
        finally:
            self.slots.release()


def _routed(scope: Scope) -> bool:
    """Some route of the app takes this path and method (Starlette puts the app in the scope)."""
    app = scope.get("app")
    routes = getattr(getattr(app, "router", None), "routes", None)
    if routes is None:
        return True  # not under a Starlette app: check everything
    return any(route.matches(scope)[0] is Match.FULL for route in routes)


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}


async def _close_handshake(receive: Receive, send: Send, code: int, reason: str) -> None:
    """Accept and close at once with `code`, so that clients see the reason (not a bare 403)."""
    message = await receive()
    if message["type"] != "websocket.connect":
        return
    await send({"type": "websocket.accept"})
    await send({"type": "websocket.close", "code": code, "reason": reason[:120]})
