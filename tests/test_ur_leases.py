"""With leases on, a world's UR ports are open only while the world is lent: a connection to
a world that is not lent is closed at once; while lent, ur-rtde 1.6.5 receives from it; when
the lease ends, its connections are closed and its controller is fresh for the next holder.
RTDE and the Dashboard carry no token, so the lease is the only gate (the guide says so).
"""

from __future__ import annotations

import socket
from collections.abc import Iterator

import httpx
import pytest

from tests.conftest import Server, wait_for
from tests.ur_judge import DASHBOARD, RTDE, RawRtde, ur_server

rtde_receive = pytest.importorskip("rtde_receive")  # the `test` extra: ur-rtde==1.6.5
ADMIN = "admin-" + "u" * 26
AUTH = {"Authorization": f"Bearer {ADMIN}"}


@pytest.fixture(scope="module")
def ur(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, list[str]]]:
    extra = ("--token", ADMIN, "--leases", "optional")
    with ur_server(2, tmp_path_factory.mktemp("ur-leases"), extra) as pair:
        yield pair


def _closed_at_once(host: str, port: int) -> bool:
    with socket.create_connection((host, port), timeout=5) as sock:
        try:
            return sock.recv(100) == b""
        except ConnectionResetError:
            return True


def _open(server: Server, world: int) -> bool:
    return bool(httpx.get(f"{server.url}/v1/ur").json()["worlds"][world]["open"])


def test_ports_open_only_while_the_world_is_lent(ur) -> None:
    server, addrs = ur
    assert not _open(server, 1)
    assert _closed_at_once(addrs[1], RTDE) and _closed_at_once(addrs[1], DASHBOARD)
    r = httpx.post(f"{server.url}/v1/leases", json={"worlds": [1], "ttl_s": 60}, headers=AUTH)
    assert r.status_code == 201, r.text
    lease = r.json()["id"]
    wait_for(lambda: _open(server, 1), "the lent world's ports open")
    assert not _open(server, 0)  # not lent: still closed
    rx = rtde_receive.RTDEReceiveInterface(addrs[1])
    raw = RawRtde(addrs[1])
    try:
        assert len(rx.getActualQ()) == 6
        raw.handshake()
        assert httpx.delete(f"{server.url}/v1/leases/{lease}", headers=AUTH).status_code == 200
        with pytest.raises((ConnectionError, OSError)):
            for _ in range(100):
                raw.read()
        wait_for(lambda: not _open(server, 1), "closed again")
        assert _closed_at_once(addrs[1], RTDE)
        assert "the lease of world 1 ended" in server.log()
    finally:
        raw.close()
        rx.disconnect()
