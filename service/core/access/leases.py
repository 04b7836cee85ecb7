"""Leases: worlds lent to one holder for a while, each lease with a token of its own.

A classroom gives each student a world; a shared CI server gives each test one. A lease names
its worlds, a label (who or what holds it), a time to live and a token; while it lasts only its
token (or the administrator's) may command its worlds (`callers.check`). Free worlds go first
come, lowest id first; when too few are free the request waits up to `wait_s` and is then
refused with the reason (503 and when the next world frees for a count, 409 for named worlds).

Tokens: `lease_<id>_<secret>`, the secret 192 random bits from `secrets`; only the SHA-256 of
the whole token is kept, compared with `hmac.compare_digest`. The id in front finds the lease
without comparing against every other. Nothing here is written to disk: every lease ends when
the service stops (a token of the last run is refused, 401, and the holder asks again).

The worlds of a lease are reset to home (through `reset`, i.e. `Control`) when it starts and
when it ends (release or expiry), as `reset_at` says. Ending is done in that order: the lease
stops being valid, its worlds are reset, then they are free; so the next holder never sees the
last one's arm, and the last one can no longer move it. One thread waits for the next expiry.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import secrets
import threading
import time
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from typing import Any

from service.core.errors import BadCommand, Conflict, NotFound, Unavailable
from service.core.sim import rules

log = logging.getLogger("armfleet.leases")

PREFIX = "lease_"
MAX_WAIT_S = 60.0
MAX_LABEL = 120


def digest(token: str) -> bytes:
    """What is kept of a token: its SHA-256."""
    return hashlib.sha256(token.encode()).digest()


def lease_id_of(token: str) -> str | None:
    """The lease id written in a lease token, None when `token` is not shaped like one."""
    if not token.startswith(PREFIX):
        return None
    lease_id, sep, secret = token[len(PREFIX) :].partition("_")
    return lease_id if sep and lease_id and secret else None


def looks_like_lease(token: str | None) -> bool:
    return token is not None and lease_id_of(token) is not None


@dataclass
class Lease:
    """One lease. `expires` is on the monotonic clock; `expires_at` on the wall clock."""

    id: str
    worlds: tuple[int, ...]
    label: str
    ttl_s: float
    expires: float
    expires_at: float
    granted_at: float
    token_digest: bytes = field(repr=False)

    def view(self, now: float) -> dict[str, Any]:
        """Its public form (never the token, nor its digest)."""
        return {
            "id": self.id,
            "worlds": list(self.worlds),
            "label": self.label,
            "ttl_s": self.ttl_s,
            "expires_in_s": round(max(0.0, self.expires - now), 3),
            "expires_at": self.expires_at,
            "granted_at": self.granted_at,
        }


@dataclass
class Counts:
    """What /metrics reports."""

    granted: int = 0
    released: int = 0
    expired: int = 0
    refused: int = 0


class LeaseBook:
    """Who holds which world, thread-safe; `reset(worlds)` sends worlds home (through Control).

    nworld: worlds of the service; reset_at: {"start", "end"} or a part of it; max_ttl_s: the
    longest time to live a lease may ask for (and renew to).
    """

    def __init__(
        self,
        nworld: int,
        reset: Callable[[list[int]], Any],
        reset_at: Collection[str] = ("start", "end"),
        max_ttl_s: float = 86_400.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.nworld = nworld
        self._reset = reset
        self.reset_at = frozenset(reset_at)
        self.max_ttl_s = max_ttl_s
        self._clock = clock
        self._cond = threading.Condition()
        self._leases: dict[str, Lease] = {}
        self._owner: dict[int, str | None] = {}  # world → lease id; None: being reset (ending)
        self.counts = Counts()
        self._stopping = False
        self._thread = threading.Thread(target=self._expire_loop, name="armfleet-leases")
        self._thread.daemon = True
        self._thread.start()

    # -- asking -----------------------------------------------------------------------------

    def grant(
        self,
        count: int | None = None,
        worlds: Sequence[object] | None = None,
        ttl_s: float = 600.0,
        label: str = "",
        wait_s: float = 0.0,
        last_try: bool = True,
    ) -> tuple[Lease, str]:
        """A new lease and its token (shown this once). Refused: Unavailable (503, a count:
        too few free) or Conflict (409, a named world is held), after waiting up to `wait_s`
        (blocking this thread; the HTTP route polls instead, with `last_try` False until its
        last attempt so that a wait is counted as one refusal)."""
        wanted = self._wanted(count, worlds)
        self._check_ttl(ttl_s)
        if not 0 <= wait_s <= MAX_WAIT_S:
            raise BadCommand("wait_s", f"must be in 0..{MAX_WAIT_S:g} s, got {wait_s}")
        if len(label) > MAX_LABEL:
            raise BadCommand("label", f"at most {MAX_LABEL} characters, got {len(label)}")
        deadline = self._clock() + wait_s
        with self._cond:
            while True:
                picked = self._pick(wanted)
                if picked is not None:
                    break
                left = deadline - self._clock()
                if left <= 0 or self._stopping:
                    self.counts.refused += last_try
                    raise self._refusal(wanted)
                self._cond.wait(left)
            lease, token = self._new(picked, ttl_s, label)
        if "start" in self.reset_at:
            self._send_home(list(lease.worlds))
        log.info("lease %s granted: worlds %s, %g s, %r", lease.id, lease.worlds, ttl_s, label)
        return lease, token

    def renew(self, lease_id: str, ttl_s: float) -> Lease:
        """Live `ttl_s` more seconds from now."""
        self._check_ttl(ttl_s)
        with self._cond:
            lease = self._get(lease_id)
            now = self._clock()
            lease.ttl_s = ttl_s
            lease.expires = now + ttl_s
            lease.expires_at = time.time() + ttl_s
            self._cond.notify_all()
            return lease

    def release(self, lease_id: str) -> Lease:
        """End a lease now: reset its worlds (if `end`), then free them."""
        with self._cond:
            lease = self._end(self._get(lease_id))
            self.counts.released += 1
        self._finish(lease)
        log.info("lease %s released", lease.id)
        return lease

    # -- reading ----------------------------------------------------------------------------

    def find(self, token: str) -> Lease | None:
        """The live lease of `token` (constant-time compare of digests), or None."""
        lease_id = lease_id_of(token)
        if lease_id is None:
            return None
        with self._cond:
            lease = self._leases.get(lease_id)
        if lease is None:
            return None
        return lease if hmac.compare_digest(lease.token_digest, digest(token)) else None

    def get(self, lease_id: str) -> Lease | None:
        with self._cond:
            return self._leases.get(lease_id)

    def owner(self, world: int) -> str | None:
        """The id of the lease holding `world` ("" while its last lease is being ended)."""
        with self._cond:
            held = self._owner.get(world, False)
        return None if held is False else (held or "")

    def held(self) -> set[int]:
        """Every world held now (by a lease, or being reset after one)."""
        with self._cond:
            return set(self._owner)

    def views(self, lease_id: str | None = None) -> list[dict[str, Any]]:
        """Public forms of every lease (or of one), oldest first."""
        now = self._clock()
        with self._cond:
            leases = list(self._leases.values())
        return [x.view(now) for x in leases if lease_id is None or x.id == lease_id]

    @property
    def active(self) -> int:
        with self._cond:
            return len(self._leases)

    def stop(self) -> None:
        """End the expiry thread (the service stops; every lease ends with it)."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        self._thread.join(timeout=5)

    # -- inside (the lock held where said) --------------------------------------------------

    def _wanted(self, count: int | None, worlds: Sequence[object] | None) -> int | list[int]:
        if (count is None) == (worlds is None):
            raise BadCommand("count", "give either `count` or `worlds`")
        if worlds is not None:
            ids = rules.world_ids(worlds, self.nworld)
            if not ids:
                raise BadCommand("worlds", "name at least one world")
            if len(set(ids)) != len(ids):
                raise BadCommand("worlds", "a world may be listed only once")
            return ids
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= self.nworld:
            raise BadCommand("count", f"must be an integer in 1..{self.nworld}, got {count!r}")
        return count

    def _check_ttl(self, ttl_s: float) -> None:
        if not 0 < ttl_s <= self.max_ttl_s:
            raise BadCommand("ttl_s", f"must be in (0, {self.max_ttl_s:g}] s, got {ttl_s}")

    def _pick(self, wanted: int | list[int]) -> list[int] | None:
        """Lock held: the worlds to lend, or None when they are not free now."""
        if isinstance(wanted, list):
            return None if any(w in self._owner for w in wanted) else wanted
        free = [w for w in range(self.nworld) if w not in self._owner][:wanted]
        return free if len(free) == wanted else None

    def _refusal(self, wanted: int | list[int]) -> Exception:
        """Lock held: why a request cannot be served now."""
        now = self._clock()
        soonest = min((x.expires for x in self._leases.values()), default=now)
        when = f"the next lease ends in {max(0.0, soonest - now):.1f} s"
        if isinstance(wanted, list):
            taken = [w for w in wanted if w in self._owner]
            return Conflict(f"worlds {taken} are leased; {when}", "worlds")
        free = self.nworld - len(self._owner)
        why = f"{wanted} world(s) asked, {free} of {self.nworld} free; {when}"
        return Unavailable(f"no free world: {why}")

    def _new(self, worlds: list[int], ttl_s: float, label: str) -> tuple[Lease, str]:
        """Lock held."""
        lease_id = secrets.token_hex(8)
        while lease_id in self._leases:
            lease_id = secrets.token_hex(8)
        token = f"{PREFIX}{lease_id}_{secrets.token_urlsafe(24)}"
        now, wall = self._clock(), time.time()
        lease = Lease(
            lease_id, tuple(worlds), label, ttl_s, now + ttl_s, wall + ttl_s, wall, digest(token)
        )
        self._leases[lease_id] = lease
        for w in worlds:
            self._owner[w] = lease_id
        self.counts.granted += 1
        self._cond.notify_all()  # the expiry thread: a new deadline
        return lease, token

    def _get(self, lease_id: str) -> Lease:
        lease = self._leases.get(lease_id)
        if lease is None:
            raise NotFound(f"no lease {lease_id!r} (released, expired, or never granted)", "id")
        return lease

    def _end(self, lease: Lease) -> Lease:
        """Lock held: the token stops working; its worlds stay held until `_finish`."""
        del self._leases[lease.id]
        for w in lease.worlds:
            self._owner[w] = None
        return lease

    def _finish(self, lease: Lease) -> None:
        """No lock held: reset the ended lease's worlds, then free them."""
        try:
            if "end" in self.reset_at:
                self._send_home(list(lease.worlds))
        finally:
            with self._cond:
                for w in lease.worlds:
                    if self._owner.get(w, "") is None:
                        del self._owner[w]
                self._cond.notify_all()

    def _send_home(self, worlds: list[int]) -> None:
        try:
            self._reset(worlds)
        except Exception:  # the service is stopping, or the engine failed: free them anyway
            log.exception("could not reset leased worlds %s", worlds)

    def _expire_loop(self) -> None:
        while True:
            with self._cond:
                if self._stopping:
                    return
                now = self._clock()
                due = [x for x in self._leases.values() if x.expires <= now]
                ended = [self._end(x) for x in due]
                self.counts.expired += len(ended)
                if not ended:
                    soonest = min((x.expires for x in self._leases.values()), default=None)
                    self._cond.wait(None if soonest is None else max(0.0, soonest - now))
                    continue
            for lease in ended:
                log.info("lease %s expired: worlds %s", lease.id, lease.worlds)
                self._finish(lease)
