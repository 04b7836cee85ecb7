"""Access: tokens, origins, command rate and client cap; the policy alone, then a real server."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import ROOT

from service import access
from service.settings import Settings

TOKEN = "s3cret-token"


def settings(**kw) -> Settings:
    return Settings(**kw)


# --------------------------------------------------------------------------- the policy alone


@pytest.mark.parametrize(
    ("host", "loopback"),
    [("127.0.0.1", True), ("127.3.2.1", True), ("::1", True), ("localhost", True),
     ("0.0.0.0", False), ("192.168.1.20", False), ("::", False), ("robots.lan", False)],
)  # fmt: skip
def test_only_loopback_addresses_count_as_private(host, loopback):
    assert access.is_loopback(host) is loopback


def test_a_public_bind_needs_a_token_or_insecure():
    with pytest.raises(ValueError, match="--token"):
        access.check_bind(settings(host="0.0.0.0"))
    access.check_bind(settings(host="0.0.0.0", token=TOKEN))
    access.check_bind(settings(host="0.0.0.0", insecure=True))
    access.check_bind(settings(host="127.0.0.1"))


def test_http_writes_need_the_bearer_token_and_reads_only_with_token_reads():
    s = settings(token=TOKEN)
    access.check_http(s, "GET", "/v1/info", {})
    with pytest.raises(access.AccessError) as err:
        access.check_http(s, "POST", "/v1/reset", {})
    assert err.value.status == 401
    with pytest.raises(access.AccessError):
        access.check_http(s, "POST", "/v1/reset", {"authorization": "Bearer wrong"})
    access.check_http(s, "POST", "/v1/reset", {"authorization": f"Bearer {TOKEN}"})
    closed = settings(token=TOKEN, token_reads=True)
    with pytest.raises(access.AccessError):
        access.check_http(closed, "GET", "/v1/info", {})
    access.check_http(closed, "GET", "/readyz", {})  # probes stay open


def test_http_writes_from_a_foreign_origin_are_forbidden():
    s = settings()
    ok = {"origin": "http://127.0.0.1:8000", "host": "127.0.0.1:8000"}
    access.check_http(s, "PUT", "/v1/worlds/0/targets", ok)
    with pytest.raises(access.AccessError) as err:
        access.check_http(
            s, "PUT", "/v1/worlds/0/targets", {**ok, "origin": "https://evil.example"}
        )
    assert err.value.status == 403
    listed = settings(allow_origins=["https://lab.example"])
    access.check_http(listed, "POST", "/v1/reset", {**ok, "origin": "https://lab.example"})


def test_websocket_grants_token_by_query_header_or_subprotocol():
    s = settings(token=TOKEN)
    anonymous = access.check_ws(s, {})
    assert anonymous.read and not anonymous.command and "token" in anonymous.reason
    assert access.check_ws(s, {}, f"rate=5&token={TOKEN}").command
    assert access.check_ws(s, {"authorization": f"Bearer {TOKEN}"}).command
    g = access.check_ws(s, {}, "", [f"armfleet.token.{TOKEN}", "armfleet"])
    assert g.command and g.subprotocol == "armfleet"
    assert not access.check_ws(s, {}, "token=nope").command
    assert not access.check_ws(settings(token=TOKEN, token_reads=True), {}).read


def test_websocket_from_a_foreign_origin_may_watch_but_not_command():
    s = settings(token=TOKEN)
    g = access.check_ws(s, {"origin": "https://evil.example", "host": "h:1"}, f"token={TOKEN}")
    assert g.read and not g.command and "origin" in g.reason
    assert access.check_ws(s, {"origin": "http://h:1", "host": "h:1"}, f"token={TOKEN}").command


def test_rate_limiter_refuses_over_the_rate_then_says_close():
    lim = access.RateLimiter(rate=10, burst=3)
    t = 100.0
    assert [lim.take(t) for _ in range(3)] == ["ok"] * 3
    assert [lim.take(t) for _ in range(3)] == ["refuse"] * 3
    assert lim.take(t) == "close"
    assert lim.take(t + 0.15) == "ok"  # a token is back 1/rate seconds later


def test_client_slots_cap_and_release():
    slots = access.ClientSlots(2)
    assert slots.acquire() and slots.acquire() and not slots.acquire()
    slots.release()
    assert slots.acquire()
    assert all(access.ClientSlots(0).acquire() for _ in range(1000))


def test_serve_refuses_a_public_address_without_a_token():
    proc = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve", "--host", "0.0.0.0", "--worlds", "1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode != 0
    assert "--token" in proc.stderr + proc.stdout
