"""Leases over HTTP: ask for worlds (POST /v1/leases), list, renew, give back.

Asking needs what any write needs (the administrator's token where the service has one); a
lease token may list, renew and release its own lease only. The rules, waits and refusals are
service.core.access.leases; these routes translate. Asking may wait (`wait_s`), polling on
the event loop.
"""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, Depends, Path, Request

from service.api.deps import get_runtime
from service.core.access.callers import Caller
from service.core.access.leases import LeaseBook
from service.core.contract.leases import LeaseList, LeaseReply, LeaseRequest, RenewRequest
from service.core.contract.replies import answers, errors
from service.core.errors import Conflict, Forbidden, NotFound, Unavailable
from service.runtime import Runtime

# Every route answers 404 when leases are off (armfleet serve --leases optional|required).
router = APIRouter(prefix="/v1", tags=["leases"], responses=errors(404))
_POLL_S = 0.05  # how often a waiting request looks for a free world
LeaseId = Annotated[str, Path(description="the lease's id", max_length=64)]


async def get_book(runtime: Annotated[Runtime, Depends(get_runtime)]) -> LeaseBook:
    if runtime.leases is None:
        if runtime.settings.access.leases == "off":
            raise NotFound("leases are off on this service (armfleet serve --leases optional)")
        raise Unavailable(runtime.error or "simulation is starting; see /readyz")
    return runtime.leases


Book = Annotated[LeaseBook, Depends(get_book)]


def _caller(request: Request) -> Caller | None:
    return getattr(request.state, "caller", None)


def _may_manage(request: Request, lease_id: str) -> None:
    """The administrator, or the lease's own token; Forbidden otherwise (404 if unknown)."""
    caller = _caller(request)
    if caller is not None and (caller.admin or caller.lease_id == lease_id):
        return
    raise Forbidden(f"lease {lease_id}: only its own token or the administrator's", "id")


@router.post(
    "/leases",
    status_code=201,
    summary="Lend free worlds (`count`) or named ones (`worlds`); the reply holds the token",
    **answers(LeaseReply, 409),
)
async def grant(book: Book, body: LeaseRequest) -> LeaseReply:
    # Waiting polls on the event loop: a worker thread per waiting request would let a few
    # waiters take every thread the service has.
    loop = asyncio.get_running_loop()
    deadline = loop.time() + body.wait_s
    while True:
        last = loop.time() >= deadline
        try:
            lease, token = book.grant(
                body.count, body.worlds, body.ttl_s, body.label, last_try=last
            )
            break
        except (Unavailable, Conflict):
            if last:
                raise
            await asyncio.sleep(min(_POLL_S, max(0.0, deadline - loop.time())))
    return LeaseReply(**lease.view(lease.expires - lease.ttl_s), token=token)


@router.get(
    "/leases",
    response_model=LeaseList,
    summary="Leases: every one for the administrator, its own for a lease token",
)
async def list_leases(book: Book, request: Request) -> LeaseList:
    caller = _caller(request)
    if caller is None and request.app.state.runtime.settings.access.token:
        raise Forbidden("listing leases needs the administrator's token or a lease's")
    own = caller.lease_id if caller is not None and caller.kind == "lease" else None
    views = book.views(own) if own else book.views()
    return LeaseList(leases=[LeaseReply(**v) for v in views])


@router.post(
    "/leases/{lease_id}/renew",
    summary="Live `ttl_s` more seconds from now",
    **answers(LeaseReply, 404),
)
async def renew(book: Book, request: Request, lease_id: LeaseId, body: RenewRequest) -> LeaseReply:
    _may_manage(request, lease_id)
    book.renew(lease_id, body.ttl_s)
    views = book.views(lease_id)
    if not views:
        raise NotFound(f"no lease {lease_id!r} (it ended just now)", "id")
    return LeaseReply(**views[0])


@router.delete(
    "/leases/{lease_id}",
    summary="Give the worlds back now (reset to home, then free)",
    **answers(LeaseReply, 404),
)
async def release(book: Book, request: Request, lease_id: LeaseId) -> LeaseReply:
    _may_manage(request, lease_id)
    lease = await asyncio.to_thread(book.release, lease_id)
    view = lease.view(lease.expires)
    return LeaseReply(**view)
