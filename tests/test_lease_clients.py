"""Where people meet leases: the clients' `lease()` (sync and async), the controller's session
world (`armfleet controller --lease`), and the `armfleet_world` fixture on its own lending
server; against a real server over real sockets."""

from __future__ import annotations

import asyncio
import os
from collections.abc import Iterator

import httpx
import numpy as np
import pytest

from clients import ArmfleetClient, AsyncArmfleetClient, Forbidden, Unauthorized
from clients.apps.lease_session import session_world
from clients.testing import LEASE_WAIT_S, LeasedWorld, lease_world
from tests.conftest import HOME, Server, metric, serve


@pytest.fixture(scope="module")
def lending(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    extra = ("--leases", "optional", "--engine", "mujoco")
    with serve(worlds=4, extra_args=extra, log_dir=tmp_path_factory.mktemp("lending")) as srv:
        yield srv


def test_the_sync_client_borrows_a_world_for_a_block(lending: Server) -> None:
    with ArmfleetClient(lending.url) as anyone:
        anyone.increment(0, "elbow_joint", 0.3)  # the last user left world 0 moved
        with anyone.lease(label="block") as mine:
            held = mine.leased
            assert held is not None and held.world == 0 and held.label == "block"
            assert np.allclose(mine.state(0).target, HOME)  # handed over at home
            mine.increment(0, "elbow_joint", 0.1)
            with pytest.raises(Forbidden, match="world 1 is not in this lease"):
                mine.increment(1, "elbow_joint", 0.1)
            with pytest.raises(Forbidden, match="world 0 is leased"):
                anyone.increment(0, "elbow_joint", 0.1)  # no token: keep off leased worlds
            assert mine.renew_lease(60).ttl_s == 60
            with mine.connect(0) as ws:  # the token rides the WebSocket handshake too
                assert ws.increment("elbow_joint", 0.1).world == 0
            token = held.token
        assert anyone.leases() == []  # given back
        assert np.allclose(anyone.state(0).target, HOME)  # and reset
    with ArmfleetClient(lending.url, token=token) as stale, pytest.raises(Unauthorized):
        stale.increment(0, "elbow_joint", 0.1)


def test_the_async_client_borrows_a_world_for_a_block(lending: Server) -> None:
    async def main() -> None:
        async with AsyncArmfleetClient(lending.url) as anyone:
            async with anyone.lease(count=2, label="pair") as mine:
                assert mine.leased is not None and mine.leased.worlds == (0, 1)
                await mine.increment(1, "elbow_joint", 0.1)
                with pytest.raises(Forbidden):
                    await mine.increment(2, "elbow_joint", 0.1)
                assert [x.id for x in await mine.leases()] == [mine.leased.id]
            assert await anyone.leases() == []

    asyncio.run(main())


def test_the_controller_takes_a_world_for_its_session_and_gives_it_back(lending: Server) -> None:
    with ArmfleetClient(lending.url) as anyone:
        with session_world(lending.url, lease=True, label="controller test") as (world, token):
            (held,) = anyone.leases()
            assert held.worlds == (world,) and held.label == "controller test"
            assert token is not None and token != ""
            with session_world(lending.url, lease_token=token) as (same, again):
                assert (same, again) == (world, token)  # a handed-out lease: its world
            assert len(anyone.leases()) == 1  # not given back by the one it was handed to
        assert anyone.leases() == []


def test_lending_refusals_say_why_over_rest(lending: Server) -> None:
    """The leases guide's answers: a time to live over `--lease-max-ttl-s` (default 86400),
    every world lent (503 with when the next lease ends), and a token this server never
    issued, as every token from before a restart is (401 saying the service restarted)."""

    with httpx.Client(base_url=lending.url, timeout=30) as http:
        granted, released = (
            metric(http, f"armfleet_leases_{x}_total") for x in ("granted", "released")
        )
        r = http.post("/v1/leases", json={"count": 1, "ttl_s": 86401})
        assert r.status_code == 422 and "ttl_s" in r.text and "86400" in r.text, r.text
        r = http.post("/v1/leases", json={"count": 4, "ttl_s": 30, "label": "all"})
        assert r.status_code == 201, r.text
        every = r.json()
        mine = {"Authorization": f"Bearer {every['token']}"}
        try:
            r = http.post("/v1/leases", json={"count": 1, "ttl_s": 30})
            assert r.status_code == 503, r.text
            assert "no free world" in r.text and "0 of 4 free" in r.text
            assert "the next lease ends in" in r.text
            r = http.post(f"/v1/leases/{every['id']}/renew", json={"ttl_s": 90000}, headers=mine)
            assert r.status_code == 422 and "86400" in r.text, r.text
            r = http.post(f"/v1/leases/{every['id']}/renew", json={"ttl_s": 60}, headers=mine)
            assert r.status_code == 200 and r.json()["ttl_s"] == 60  # the holder renews
        finally:
            given_back = http.delete(f"/v1/leases/{every['id']}", headers=mine)
            assert given_back.status_code == 200, given_back.text
        assert metric(http, "armfleet_leases_granted_total") == granted + 1
        assert metric(http, "armfleet_leases_released_total") == released + 1
        stale = {"Authorization": "Bearer lease_0123abcd_" + "x" * 32}
        r = http.post("/v1/worlds/0/increments", json={"joint": 0, "delta": 0.1}, headers=stale)
        assert r.status_code == 401 and "service restarted" in r.json()["detail"], r.text


def test_a_test_waits_for_a_world_while_every_world_is_busy(lending: Server) -> None:
    """The leases guide: "When all worlds are busy, a test waits up to a minute for one":
    `armfleet_world`'s lease (clients.testing.lease_world) is served when a busy world comes
    free, not refused. (The minute is LEASE_WAIT_S; a test of the bound would wait it out.)"""

    with httpx.Client(base_url=lending.url, timeout=30) as http:
        expired, refused = (
            metric(http, f"armfleet_leases_{x}_total") for x in ("expired", "refused")
        )
        r = http.post("/v1/leases", json={"count": 4, "ttl_s": 1.0, "label": "busy"})
        assert r.status_code == 201, r.text
        with lease_world(lending.url, label="waiting") as got:
            assert got.lease.label == "waiting" and got.world in r.json()["worlds"]
            assert [x.label for x in got.client.leases()] == ["waiting"]  # busy one: over
        assert metric(http, "armfleet_leases_expired_total") == expired + 1
        assert metric(http, "armfleet_leases_refused_total") == refused  # waited, not refused
        assert LEASE_WAIT_S == 60.0  # the guide's "up to a minute"


@pytest.mark.skipif("ARMFLEET_URL" in os.environ, reason="uses the shared server instead")
def test_armfleet_world_without_a_shared_server_leases_from_its_own(
    armfleet_world: LeasedWorld,
) -> None:
    arm, w = armfleet_world.client, armfleet_world.world
    assert np.allclose(arm.state(w).target, HOME)
    assert arm.increment(w, "elbow_joint", 0.1).world == w
    (held,) = arm.leases()
    assert "test_armfleet_world_without_a_shared_server" in held.label
    assert held.ttl_s == 900  # the leases guide: a dead test's lease expires by itself (15 min)
