"""The client's exceptions, one per way a call can fail, and how a server reply maps to them.

Every error the library raises is an `ArmfleetError`, so `except ArmfleetError` catches all of
them; the subclasses say what went wrong in terms a caller acts on (fix the request, wait for
readiness, give up on an unknown world) rather than in status codes.
"""

from __future__ import annotations

from typing import Any

import orjson


class ArmfleetError(Exception):
    """Any error from the service. `status` is the HTTP status (None: no HTTP reply at all) and
    `detail` the server's `detail` as it sent it (a string, or FastAPI's list of errors)."""

    def __init__(self, status: int | None, detail: Any, message: str | None = None) -> None:
        self.status = status
        self.detail = detail
        super().__init__(message or format_detail(detail))


class InvalidRequest(ArmfleetError):
    """422 (or 400): the request was refused as invalid; `detail` says which field and why."""


class NotFound(ArmfleetError):
    """404: no such world (or route)."""


class Conflict(ArmfleetError):
    """409: not possible in the current mode (e.g. step while not paused)."""


class Unauthorized(ArmfleetError):
    """401: no token, a wrong one, or a lease token whose lease has ended."""


class Forbidden(ArmfleetError):
    """403: this token may not command that world (not in its lease) or that route."""


class PayloadTooLarge(ArmfleetError):
    """413: request body over the server's limit."""


class NotReady(ArmfleetError):
    """503: the service is up but the simulation is still starting (or failed to start)."""


class Unreachable(ArmfleetError):
    """No reply at all: connection refused, reset or timed out. `status` is None."""


class CommandRejected(ArmfleetError):
    """A WebSocket command answered with `{"op": "error"}`; `detail` is the server's text."""


_BY_STATUS: dict[int, type[ArmfleetError]] = {
    400: InvalidRequest,
    401: Unauthorized,
    403: Forbidden,
    404: NotFound,
    409: Conflict,
    413: PayloadTooLarge,
    422: InvalidRequest,
    503: NotReady,
}


def format_detail(detail: Any) -> str:
    """FastAPI's `[{"loc": [...], "msg": ...}]` as `body.joint.bogus: unknown joint ...`."""
    if isinstance(detail, list):
        parts = []
        for err in detail:
            if isinstance(err, dict):
                loc = ".".join(str(p) for p in err.get("loc", []))
                parts.append(f"{loc}: {err.get('msg', '')}" if loc else str(err.get("msg", "")))
            else:
                parts.append(str(err))
        return "; ".join(parts)
    return str(detail)


def error_for(status: int, body: bytes) -> ArmfleetError:
    """The exception for a non-2xx reply, carrying the server's `detail`."""
    try:
        detail = orjson.loads(body).get("detail", body.decode(errors="replace"))
    except (orjson.JSONDecodeError, AttributeError):
        detail = body.decode(errors="replace") or f"HTTP {status}"
    cls = _BY_STATUS.get(status, ArmfleetError)
    return cls(status, detail, f"HTTP {status}: {format_detail(detail)}")


def unreachable(url: str, why: BaseException | str) -> Unreachable:
    """`Unreachable` for `url`, saying why in a few words (an exception's text or its type)."""
    text = why if isinstance(why, str) else str(why) or type(why).__name__
    return Unreachable(None, f"{url}: {text}")
