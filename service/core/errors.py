"""Domain errors, raised anywhere and mapped to a status code in exactly one place.

Every surface (HTTP routes, WebSocket frames, ROS 2, rosbridge, Foxglove, replay) raises these; the
app's one exception handler turns them into HTTP replies and `wire.error_frame` into WebSocket error
frames, so an unknown world is a 404 whichever way the command came in.
"""

from __future__ import annotations


class ArmfleetError(Exception):
    """A request that cannot be served; `status` is its HTTP status (STATUS), `field` what was
    wrong."""

    def __init__(self, detail: str, field: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.field = field

    def __str__(self) -> str:
        return f"{self.field}: {self.detail}" if self.field else self.detail

    @property
    def status(self) -> int:
        """The HTTP status: STATUS's for this class, or for the nearest base class it names."""
        return next(STATUS[kind] for kind in type(self).__mro__ if kind in STATUS)


class BadCommand(ArmfleetError):
    """The command itself is invalid (unknown joint, wrong lengths, NaN, out of limits)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message, field)
        self.message = message


class UnknownWorld(ArmfleetError):
    """The world id is not in 0..nworld-1."""

    def __init__(self, worlds: int | list[int] | str, nworld: int) -> None:
        if isinstance(worlds, int):
            what = f"world {worlds} does not"
        else:  # a list of ids, or a range as written in a `worlds` query
            shown = worlds if isinstance(worlds, list) else repr(worlds)
            what = f"worlds {shown} do not"
        super().__init__(f"{what} exist (0..{nworld - 1})", "world")
        self.worlds = worlds


class NotFound(ArmfleetError):
    """A named thing (snapshot, recording) that does not exist."""


class Forbidden(ArmfleetError):
    """This caller may not command that world (access/callers.py decides), nothing changed."""


class OverRate(ArmfleetError):
    """A lease's commands, over all its connections together, came faster than its rate."""


class BadToken(ArmfleetError):
    """A token that is neither the administrator's nor a live lease's."""


class NotPaused(ArmfleetError):
    """Stepping by request only makes sense while paused."""


class Conflict(ArmfleetError):
    """The request is valid but does not fit the current state (other model, other size)."""


class ProtectiveStopped(Conflict):
    """A command that would move the arm of a protective-stopped world (core/sim/safety.py),
    until the stop is unlocked or the world reset."""


class Unavailable(ArmfleetError):
    """The engine is starting, failed or is being rebuilt (retry later)."""


class CannotWrite(ArmfleetError):
    """A file the request asked for (recording, snapshot) cannot be written: the disk is full,
    the folder read-only, a FIFO has no reader; the detail names the path and cause."""


# The one place an error gets its HTTP status (the app's handler, the access middleware and
# WebSocket error frames read it as `exc.status`); a subclass not named has its base's.
STATUS: dict[type[ArmfleetError], int] = {
    ArmfleetError: 400,
    BadCommand: 422,
    UnknownWorld: 404,
    NotFound: 404,
    Forbidden: 403,
    OverRate: 429,
    BadToken: 401,
    NotPaused: 409,
    Conflict: 409,
    Unavailable: 503,
    CannotWrite: 507,
}
