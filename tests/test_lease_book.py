"""The LeaseBook on its own (service.core.access.leases): what a lease token is and what is
kept of it, first come first served from many threads, waiting, the reasons of refusals,
and the order in which an ending lease stops working, resets its worlds and frees them."""

from __future__ import annotations

import base64
import threading
import time

import pytest

from service.core.access.callers import Caller, Gate
from service.core.access.leases import LeaseBook, digest
from service.core.access.settings import AccessSettings
from service.core.errors import BadCommand, Conflict, Forbidden, Unavailable


class Resets:
    """Records the resets a book asks for, and whether the worlds were still held then."""

    def __init__(self) -> None:
        self.calls: list[tuple[list[int], set[int]]] = []
        self.book: LeaseBook | None = None

    def __call__(self, worlds: list[int]) -> None:
        assert self.book is not None
        self.calls.append((worlds, self.book.held() & set(worlds)))


def book(nworld: int = 4, **kw: object) -> tuple[LeaseBook, Resets]:
    resets = Resets()
    b = LeaseBook(nworld, resets, **kw)  # type: ignore[arg-type]
    resets.book = b
    return b, resets


def test_a_token_has_192_random_bits_and_only_its_digest_is_kept() -> None:
    b, _ = book()
    lease, token = b.grant(count=1, ttl_s=60)
    secret = token.split("_", 2)[2]
    assert len(base64.urlsafe_b64decode(secret + "=" * (-len(secret) % 4))) * 8 >= 128
    assert lease.token_digest == digest(token)
    assert token not in repr(lease) and token not in str(vars(lease))
    assert b.find(token) is lease
    assert b.find(token[:-1] + ("A" if token[-1] != "A" else "B")) is None  # one char off
    assert b.find(f"lease_{lease.id}_") is None and b.find("not-a-lease") is None
    b.stop()


def test_forty_threads_at_once_on_thirty_two_worlds() -> None:
    b, _ = book(32)
    barrier, got, refused = threading.Barrier(40), [], []

    def ask() -> None:
        barrier.wait()
        try:
            got.append(b.grant(count=1, ttl_s=60)[0].worlds[0])
        except Unavailable as exc:
            refused.append(str(exc))

    threads = [threading.Thread(target=ask) for _ in range(40)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(got) == list(range(32)) and len(refused) == 8
    assert all("0 of 32 free" in r for r in refused) and b.counts.refused == 8
    b.stop()


def test_refusals_say_why_and_nothing_is_half_granted() -> None:
    b, _ = book(4)
    b.grant(worlds=[1, 2], ttl_s=60)
    with pytest.raises(Conflict, match=r"worlds \[2\] are leased"):
        b.grant(worlds=[0, 2], ttl_s=60)
    assert b.held() == {1, 2}  # world 0 was not taken by the refused request
    with pytest.raises(Unavailable, match="3 world\\(s\\) asked, 2 of 4 free"):
        b.grant(count=3, ttl_s=60)
    for kwargs, field in (
        ({"count": 0}, "count"),
        ({"count": 1, "worlds": [0]}, "count"),
        ({"worlds": [0, 0]}, "worlds"),
        ({"worlds": [9]}, "world"),
        ({"count": 1, "ttl_s": 0}, "ttl_s"),
        ({"count": 1, "wait_s": 61}, "wait_s"),
    ):
        with pytest.raises((BadCommand, Exception)) as err:
            b.grant(**kwargs)  # type: ignore[arg-type]
        assert getattr(err.value, "field", None) == field, (kwargs, err.value)
    b.stop()


def test_a_waiting_request_is_served_when_a_lease_ends() -> None:
    b, _ = book(1)
    first, _ = b.grant(count=1, ttl_s=60)
    # t0 before the timer starts: the release comes 0.3 s after t0 at the earliest (a reading
    # taken after the start undercounts by however long a loaded box kept this thread waiting)
    t0 = time.monotonic()
    threading.Timer(0.3, b.release, args=(first.id,)).start()
    second, _ = b.grant(count=1, ttl_s=60, wait_s=5)
    assert 0.25 < time.monotonic() - t0 < 3 and second.worlds == (0,)
    b.stop()


def test_an_ending_lease_stops_working_then_resets_then_frees() -> None:
    b, resets = book(2)
    lease, token = b.grant(count=1, ttl_s=0.3)
    assert resets.calls == [([0], {0})]  # reset at the start, the world already held
    # The expiry thread ends it 0.3 s on; on a loaded box its turn may come later: wait for the
    # world to come free (the last step), generously, rather than sleep a fixed 0.6 s.
    deadline = time.monotonic() + 30
    while b.held() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert b.find(token) is None and b.get(lease.id) is None
    assert resets.calls[-1] == ([0], {0})  # reset at the end while still held: nobody else had it
    assert b.held() == set() and b.counts.expired == 1


def test_the_gate_checks_worlds_for_each_kind_of_caller() -> None:
    b, _ = book(4)
    lease, _ = b.grant(worlds=[2], ttl_s=60)
    s = AccessSettings(token="admin", leases="optional")
    gate = Gate(s, b, 4, lambda: _Always())
    holder, anyone = Caller("lease", lease.id), Caller("open")
    gate.check(holder, [2], "ws")
    gate.check(Caller("admin"), None, "ws")
    gate.check(anyone, [1], "ws")  # a free world
    for caller, worlds, why in (
        (holder, [1], "world 1 is not in this lease"),
        (holder, None, "needs the administrator"),
        (anyone, [2], "world 2 is leased"),
        (anyone, None, "some are leased"),
    ):
        with pytest.raises(Forbidden, match=why):
            gate.check(caller, worlds, "rosbridge")
    assert gate.forbidden == {"rosbridge": 4}
    b.release(lease.id)
    with pytest.raises(Forbidden, match="has ended"):
        gate.check(holder, [2], "ws")
    required = Gate(AccessSettings(token="admin", leases="required"), b, 4, lambda: _Always())
    with pytest.raises(Forbidden, match="need a lease"):
        required.check(anyone, [0], "http")
    b.stop()


class _Always:
    detail = ""

    def take(self) -> str:
        return "ok"


def test_a_lease_has_one_rate_limit_over_all_its_connections() -> None:
    from service.core.access.rates import RateLimiter
    from service.core.errors import OverRate

    b, _ = book(2)
    lease, _ = b.grant(count=1, ttl_s=60)
    gate = Gate(AccessSettings(leases="optional"), b, 2, lambda: RateLimiter(1.0, 2))
    holder = Caller("lease", lease.id)
    gate.check(holder, [0], "ws")  # one connection
    gate.check(holder, [0], "http")  # another: the same bucket
    with pytest.raises(OverRate, match="this lease's rate"):
        gate.check(holder, [0], "rosbridge")
    b.stop()
