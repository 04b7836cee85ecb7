"""Ticks first over HTTP: a command request takes its turn in the tick's command budget.

Why a middleware: every command route runs on the event loop like a socket's commands do, so
it takes the same turns (service/core/sim/command_share.py) before it runs, and is charged the
event loop's CPU meanwhile after. One place covers the routes added later, as the access check
does.
Reads never wait: they take no tick's budget (a read that waits for a tick waits for it anyway).
A command that finds no turn within the longest wait is answered 503 naming that limit, with
`Retry-After` (counted as refused in /metrics).
"""

from __future__ import annotations

from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from service.core.access.policy import is_command
from service.core.sim.command_share import cpu_now, turn


class TakeTurns:
    """HTTP commands wait for the tick's command budget in real time (`--ticks-first`)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not is_command(scope["method"], scope["path"]):
            return await self.app(scope, receive, send)
        loop = scope["app"].state.runtime.loop  # None while the service starts: no ticks yet
        if loop is None:
            return await self.app(scope, receive, send)
        share = loop.share
        if not await turn(share):  # no turn within the longest wait: busy, try later
            busy = JSONResponse(
                {"detail": share.busy_detail}, status_code=503, headers={"Retry-After": "1"}
            )
            return await busy(scope, receive, send)
        t0 = cpu_now()
        try:
            await self.app(scope, receive, send)
        finally:  # the thread's CPU meanwhile (others' work between its awaits too): a tick at most
            share.spent(min(cpu_now() - t0, share.tick_dt))
