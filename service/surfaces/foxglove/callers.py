"""Who each Foxglove client is: its token arrives as the parameter `armfleet.token`.

Foxglove's WebSocket handshake has no place for a token (its app opens the socket itself), so
a client presents one by setting that parameter; the live surface answers with no parameters,
so the value is never published to any client. A client that presents none is the tokenless
caller (service.core.access.callers.identify), refused where the service has a token. Each client
has its own command rate limiter, as each socket of the other surfaces does.
"""

from __future__ import annotations

from collections import OrderedDict

from service.core.access.callers import Caller, identify
from service.core.access.leases import LeaseBook
from service.core.access.policy import RateLimiter
from service.core.access.settings import AccessSettings
from service.core.errors import BadToken

TOKEN_PARAMETER = "armfleet.token"
_MAX_KEPT = 1024  # clients remembered (the SDK does not tell when one leaves): the oldest go


class ClientCallers:
    """client id → (its caller, its rate limiter); thread-safe enough for the SDK's threads
    (one dict operation at a time)."""

    def __init__(self, access: AccessSettings) -> None:
        self.access = access
        self._known: OrderedDict[int, tuple[Caller, RateLimiter]] = OrderedDict()

    def present(self, client_id: int, token: object, book: LeaseBook | None) -> None:
        """The client set `armfleet.token`; BadToken (it is then tokenless again) if wrong."""
        self._known.pop(client_id, None)
        caller = identify(self.access, book, token if isinstance(token, str) else None)
        self._keep(client_id, caller)

    def of(self, client_id: int, book: LeaseBook | None) -> tuple[Caller, RateLimiter]:
        """The client's caller and limiter; BadToken when it must present a token first."""
        known = self._known.get(client_id)
        if known is not None:
            return known
        try:
            caller = identify(self.access, book, None)
        except BadToken as exc:
            raise BadToken(f"{exc.detail}: set the parameter {TOKEN_PARAMETER}") from None
        return self._keep(client_id, caller)

    def _keep(self, client_id: int, caller: Caller) -> tuple[Caller, RateLimiter]:
        while len(self._known) >= _MAX_KEPT:
            self._known.popitem(last=False)
        known = (caller, RateLimiter(self.access.command_rate, self.access.command_burst))
        self._known[client_id] = known
        return known
