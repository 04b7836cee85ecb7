"""A world for as long as a program runs: `armfleet controller --lease` takes one and gives it
back on exit, renewing it meanwhile so that a long lesson does not run out.

    with session_world(url, admin_token, lease=True, label="alice") as (world, token):
        run_the_ui(url, world, token)
"""

from __future__ import annotations

import contextlib
import getpass
import threading
from collections.abc import Iterator

from clients.client import ArmfleetClient
from clients.errors import ArmfleetError

SESSION_TTL_S = 300.0  # a lease dies this long after its program does (crashed, killed)


@contextlib.contextmanager
def session_world(
    url: str,
    token: str | None = None,
    world: int = 0,
    lease: bool = False,
    lease_token: str | None = None,
    label: str | None = None,
) -> Iterator[tuple[int, str | None]]:
    """(the world to drive, the token to drive it with) for the block.

    lease: take a free world (asking with `token`, where the service needs one to lend) and
    give it back after; lease_token: drive the first world of a lease someone handed out (not
    given back: it is theirs); neither: `world` with `token`, as before leases.
    """
    if lease_token:
        with ArmfleetClient(url, token=lease_token) as mine:
            held = mine.leases()  # Unauthorized (401) once it has ended
        if not held:
            raise ArmfleetError(None, "lease: it has ended", "lease: it has ended")
        yield held[0].world, lease_token
        return
    if not lease:
        yield world, token
        return
    who = label or f"controller {getpass.getuser()}"
    with (
        ArmfleetClient(url, token=token) as lender,
        lender.lease(1, ttl_s=SESSION_TTL_S, label=who) as mine,
    ):
        assert mine.leased is not None
        stop = threading.Event()
        renewer = threading.Thread(target=_renew, args=(mine, stop), daemon=True)
        renewer.start()
        try:
            yield mine.leased.world, mine.leased.token
        finally:
            stop.set()
            renewer.join(timeout=5)


def _renew(client: ArmfleetClient, stop: threading.Event) -> None:
    """Renew every third of the time to live until `stop` (errors: tried again next time)."""
    while not stop.wait(SESSION_TTL_S / 3):
        with contextlib.suppress(ArmfleetError):
            client.renew_lease(SESSION_TTL_S)
