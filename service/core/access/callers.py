"""Who sends a command, and whether they may command the worlds it touches: one check, once.

Every surface learns its caller once (an HTTP request's bearer token, a socket's handshake, a
Foxglove client's `armfleet.token` parameter) with `identify`, and runs commands through
`Control.acting_for(caller)`; `Control.run` calls `Gate.check` with the worlds the command
touches (`Command.touches`, None: every world) before anything is staged. So REST, both
WebSocket sockets, the page, rosbridge and Foxglove give the same answer: `Forbidden` (403,
naming the world; a WebSocket error frame with the command's id), and nothing changes.

Callers:
- admin: the server's `--token` (or anyone, when the service has no token): every world;
- lease: a lease token: its lease's worlds only, while the lease lives;
- open: no token, on a service that takes tokenless writes (no `--token`): free worlds only
  (every world, unless a lease holds some), and none at all with `--leases required`.
"""

from __future__ import annotations

import hmac
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

from service.core.access.leases import LeaseBook, looks_like_lease
from service.core.access.settings import AccessSettings
from service.core.errors import BadToken, Forbidden, OverRate


@dataclass(frozen=True)
class Caller:
    """Who is asking. `lease_id` for a lease holder; `label` their lease's label."""

    kind: Literal["admin", "lease", "open"]
    lease_id: str | None = None

    @property
    def admin(self) -> bool:
        return self.kind == "admin"

    def describe(self) -> str:
        return f"lease {self.lease_id}" if self.lease_id else self.kind


ADMIN = Caller("admin")
OPEN = Caller("open")


def identify(settings: AccessSettings, book: LeaseBook | None, presented: str | None) -> Caller:
    """The caller a presented token stands for; BadToken (401) for a wrong one.

    With no `--token`, a tokenless caller is the administrator while leases are off, and
    `open` otherwise (it must keep off leased worlds)."""
    if presented and settings.token and _same(presented, settings.token):
        return ADMIN
    if looks_like_lease(presented):
        assert presented is not None
        lease = None if book is None else book.find(presented)
        if lease is None:
            raise BadToken(
                "this lease token is not valid: the lease was released or expired, or the "
                "service restarted (leases end with it); ask for a new lease"
            )
        return Caller("lease", lease.id)
    if settings.token:
        if presented is None:
            raise BadToken("writes need a token: the administrator's or a lease's")
        raise BadToken("wrong token: neither the administrator's nor a lease's")
    return ADMIN if settings.leases == "off" else OPEN


def _same(a: str, b: str) -> bool:
    return hmac.compare_digest(a.encode(), b.encode())


def book_of(control: object) -> LeaseBook | None:
    """The LeaseBook behind a Control's gate (None: leases off, or not started)."""
    gate = getattr(control, "gate", None)
    return gate.book if isinstance(gate, Gate) else None


class Bucket(Protocol):
    """A token bucket (access.RateLimiter): take() says "ok" or not."""

    detail: str

    def take(self) -> str: ...


class Gate:
    """The one check of a command's worlds against its caller (see the module docstring),
    counting what it forbids by surface (`forbidden`, for /metrics). A lease's commands also
    pass one bucket of its own (`bucket()` makes it), whatever connections they come by.
    Called by Control under its order lock: one check at a time."""

    def __init__(
        self, settings: AccessSettings, book: LeaseBook, nworld: int, bucket: Callable[[], Bucket]
    ) -> None:
        self.required = settings.leases == "required"
        self.book = book
        self.nworld = nworld
        self.forbidden: dict[str, int] = {}
        self._bucket = bucket
        self._buckets: dict[str, Bucket] = {}

    def check(self, caller: Caller, worlds: Sequence[int] | None, source: str) -> None:
        """Forbidden naming the first world `caller` may not command (OverRate when a lease
        sends too fast); None when allowed."""
        if caller.admin:
            return
        why = self._why(caller, worlds)
        if why is not None:
            self.forbidden[source] = self.forbidden.get(source, 0) + 1
            raise Forbidden(why, "world")
        if caller.lease_id is not None:
            self._take(caller.lease_id)

    def _take(self, lease_id: str) -> None:
        bucket = self._buckets.get(lease_id)
        if bucket is None:
            if len(self._buckets) > 4 * max(1, self.book.active):  # drop ended leases' buckets
                live = {v["id"] for v in self.book.views()}
                self._buckets = {k: v for k, v in self._buckets.items() if k in live}
            bucket = self._buckets[lease_id] = self._bucket()
        if bucket.take() != "ok":
            raise OverRate(f"this lease's {bucket.detail}", "lease")

    def _why(self, caller: Caller, worlds: Sequence[int] | None) -> str | None:
        if caller.kind == "lease":
            lease = self.book.get(caller.lease_id or "")
            if lease is None:
                return f"lease {caller.lease_id} has ended (released or expired)"
            if worlds is None:
                return "this command changes every world: it needs the administrator's token"
            for w in worlds:
                if w not in lease.worlds:
                    return f"world {w} is not in this lease (its worlds: {list(lease.worlds)})"
            return None
        if self.required:
            return "commands need a lease token or the administrator's (--leases required)"
        held = self.book.held()
        if worlds is None:
            return None if not held else "this command changes every world, and some are leased"
        for w in worlds:
            if w in held:
                return f"world {w} is leased; only its lease token may command it"
        return None
