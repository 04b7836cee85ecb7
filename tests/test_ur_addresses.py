"""Where each world's UR controller listens: the loopback mapping (more than 254 worlds
included), the user's ranges and lists, and the consent a non-loopback address needs (the
same as `--host`'s), each refusal naming `ur_addresses`; and a hard open-file limit too low
for the listeners, which `armfleet serve` refuses at once naming `ur_worlds`."""

from __future__ import annotations

import resource
import subprocess
import sys
import time

import pytest

from service.core.access.settings import AccessSettings
from service.surfaces.ur import addresses
from tests.conftest import free_port
from tests.ur_judge import loopback_block


def test_the_loopback_mapping_gives_every_world_its_own_address() -> None:
    got = [addresses.loopback_address(w) for w in range(600)]
    assert got[0] == "127.0.1.1" and got[253] == "127.0.1.254" and got[254] == "127.0.2.1"
    assert len(set(got)) == 600
    assert not any(a.endswith((".0", ".255")) for a in got)
    with pytest.raises(ValueError, match="loopback mapping holds"):
        addresses.loopback_address(addresses.MAX_LOOPBACK_WORLDS)


def test_ranges_and_lists_in_order() -> None:
    assert addresses.parse_addresses("10.0.0.9-10.0.0.11, 10.0.0.20") == [
        "10.0.0.9", "10.0.0.10", "10.0.0.11", "10.0.0.20",
    ]  # fmt: skip
    assert addresses.parse_addresses("10.0.0.3-10.0.0.1") == ["10.0.0.3", "10.0.0.2", "10.0.0.1"]
    for bad, words in (
        ("10.0.0.1,10.0.0.1", "listed twice"),
        ("10.0.0.x", "not an IPv4"),
        ("::1", "not an IPv4"),
        ("10.0.0.255", "cannot be one robot's"),
        ("1-2-3", "not an address or a range"),
    ):
        with pytest.raises(ValueError, match=words) as err:
            addresses.parse_addresses(bad)
        assert str(err.value).startswith("ur_addresses:")


def test_off_loopback_needs_the_same_consent_as_the_http_bind() -> None:
    spec = "192.168.56.10-192.168.56.11"
    with pytest.raises(ValueError, match=r"ur_addresses: refusing to bind 192\.168\.56\.10"):
        addresses.assign([0, 1], spec, AccessSettings())
    for consent in (AccessSettings(insecure=True), AccessSettings(token="t" * 20)):
        assert addresses.assign([0, 1], spec, consent) == {0: "192.168.56.10", 1: "192.168.56.11"}
    assert addresses.assign([0, 1], "127.9.0.1-127.9.0.2", AccessSettings())[1] == "127.9.0.2"
    with pytest.raises(ValueError, match="1 addresses for 2 worlds"):
        addresses.assign([0, 1], "127.9.0.1", AccessSettings())
    assert addresses.assign([3], None, AccessSettings()) == {3: "127.0.1.4"}
    assert addresses.descriptors(32) == 160


def test_a_hard_open_file_limit_too_low_refuses_to_start_naming_ur_worlds() -> None:
    """A server process whose hard RLIMIT_NOFILE (as `prlimit` or a container sets it) is
    below what its UR ports want exits with the reason before it builds the engine."""
    worlds, limit = 4, 256  # 4 worlds want 20 listeners + 512 spare: more than 256
    assert addresses.descriptors_wanted(worlds) > limit

    def lower_the_limit() -> None:  # in the child, before it runs armfleet
        resource.setrlimit(resource.RLIMIT_NOFILE, (limit, limit))

    block = loopback_block(worlds)
    cmd = [sys.executable, "-m", "service.cli", "serve", "--worlds", str(worlds),
           "--engine", "mujoco", "--mode", "paused", "--port", str(free_port()),
           "--ur", "--ur-addresses", f"{block[0]}-{block[-1]}"]  # fmt: skip
    t0 = time.monotonic()
    done = subprocess.run(
        cmd, preexec_fn=lower_the_limit, capture_output=True, text=True, timeout=60
    )
    said = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stdout + done.stderr
    assert said[-1].startswith("armfleet serve: ur_worlds: ") and "Traceback" not in done.stderr
    assert f"hard limit is {limit} (ulimit -Hn)" in said[-1]
    assert f"want {addresses.descriptors_wanted(worlds)} open files" in said[-1]
    assert "ready at" not in done.stdout + done.stderr  # no engine built, nothing served
    print(f"refused in {time.monotonic() - t0:.1f} s: {said[-1]}")
