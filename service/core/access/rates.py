"""How fast one client may command: a token bucket per connection, on every surface.

Why apart from the policy: the bucket is the one rule of "too fast" that sockets (per socket),
rosbridge and Foxglove (per client) and HTTP (per keep-alive connection, `ConnectionRates`)
share, and the HTTP side keeps buckets of its own between requests. A refusal names the limit:
an error frame on a socket, 429 over HTTP, both counted as `refused` in /metrics.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from typing import Any


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


class ConnectionRates:
    """One RateLimiter per HTTP connection (the client's address and port: a keep-alive
    connection keeps its bucket from request to request). The `keep` most recently used are
    kept; an older connection that comes back starts with a full bucket."""

    def __init__(self, rate: float, burst: int | None = None, keep: int = 4096) -> None:
        self.rate, self.burst, self.keep = rate, burst, keep
        self._buckets: OrderedDict[Any, RateLimiter] = OrderedDict()

    def of(self, client: Any) -> RateLimiter:
        """The bucket of `client` (an ASGI scope's `client`: (host, port), or None)."""
        key = tuple(client) if client else None
        bucket = self._buckets.get(key)
        if bucket is None:
            bucket = self._buckets[key] = RateLimiter(self.rate, self.burst)
            while len(self._buckets) > self.keep:
                self._buckets.popitem(last=False)
        else:
            self._buckets.move_to_end(key)
        return bucket
