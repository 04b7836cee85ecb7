"""pytest fixtures that run a real armfleet server (see `clients.testing.serve`).

Registered as the `armfleet` pytest plugin when armfleet is installed, so a project that
depends on armfleet gets the fixtures without any conftest:

    def test_elbow_moves(armfleet_server):
        with armfleet_server.client() as arm:
            arm.increment(0, "elbow_joint", 0.1)

- `armfleet_server`: one 4-world realtime server shared by the tests of a module.
- `armfleet_server_factory`: `factory(worlds=16, mode="paused", ...)` (the arguments of
  `serve()`) starts a server for one test; all it started stop when the test ends.
- `armfleet_world`: one world of its own for one test, leased (reset to home, given back
  after the test) from the shared server named by ARMFLEET_URL (token: ARMFLEET_TOKEN, if the
  server needs one to lend), else from a 4-world server of the module's own that lends
  (`--leases optional`). pytest-xdist workers each get their own world:
  `ARMFLEET_URL=http://ci-box:8000 pytest -n 4`.
- `armfleet_ur_world`: the same, on a server with UR ports (`serve --ur`): a `UrWorld`, the
  leased world (`client`, `world`, `lease`, as `armfleet_world`'s) with its UR controller's
  `address` (from `GET /v1/ur`), so that a ur_rtde program under test connects to
  `ur.address`. Without ARMFLEET_URL, a 4-world server of the module's
  own lends, with its UR ports on a random loopback block (tests at once never share one).

      def test_moves(armfleet_ur_world):
          rtde_c = rtde_control.RTDEControlInterface(armfleet_ur_world.address)

      def test_elbow_moves(armfleet_world):
          arm, w = armfleet_world.client, armfleet_world.world
          arm.increment(w, "elbow_joint", 0.1)
"""

from __future__ import annotations

import os
import random
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, ExitStack
from dataclasses import dataclass
from typing import Any

import httpx
import pytest

from clients.testing import LeasedWorld, Server, lease_world, serve

ServerFactory = Callable[..., Server]


@pytest.fixture(scope="module")
def armfleet_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """A 4-world realtime server for the tests of one module (its log in pytest's tmp dir)."""
    with serve(worlds=4, log_dir=tmp_path_factory.mktemp("armfleet")) as server:
        yield server


@pytest.fixture
def armfleet_server_factory(tmp_path: Any) -> Iterator[ServerFactory]:
    """Start servers of other sizes or options inside one test: `factory(worlds=16)`."""
    with ExitStack() as stack:

        def start(**kwargs: Any) -> Server:
            kwargs.setdefault("log_dir", tmp_path)
            return stack.enter_context(serve(**kwargs))

        yield start


@pytest.fixture(scope="module")
def armfleet_lending_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """A 4-world realtime server that lends worlds (`armfleet_world` without ARMFLEET_URL)."""
    log_dir = tmp_path_factory.mktemp("armfleet-lending")
    with serve(worlds=4, extra_args=("--leases", "optional"), log_dir=log_dir) as server:
        yield server


def _leased(request: pytest.FixtureRequest, own_server: str) -> AbstractContextManager[LeasedWorld]:
    """A world leased for this test from ARMFLEET_URL (token: ARMFLEET_TOKEN), else from the
    module's own server, the fixture named `own_server`; labelled with the worker and test."""
    url = os.environ.get("ARMFLEET_URL") or request.getfixturevalue(own_server).url
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    label = f"pytest {worker} {request.node.nodeid}"[:120]
    return lease_world(url, os.environ.get("ARMFLEET_TOKEN"), label)


@pytest.fixture
def armfleet_world(request: pytest.FixtureRequest) -> Iterator[LeasedWorld]:
    """A leased world of its own for this test (see the module docstring)."""
    with _leased(request, "armfleet_lending_server") as world:
        yield world


@pytest.fixture(scope="module")
def armfleet_ur_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """A 4-world realtime server that lends worlds and gives each UR ports (`--ur`), on
    127.A.B.1-4 of a random block so that servers of tests running at once never collide."""
    a, b = random.randrange(2, 250), random.randrange(0, 250)
    args = ("--leases", "optional", "--ur", "--ur-addresses", f"127.{a}.{b}.1-127.{a}.{b}.4")
    with serve(worlds=4, extra_args=args, log_dir=tmp_path_factory.mktemp("armfleet-ur")) as s:
        yield s


@dataclass
class UrWorld(LeasedWorld):
    """A leased world with UR ports: `address` is its controller's (RTDE, Dashboard, ...)."""

    address: str


@pytest.fixture
def armfleet_ur_world(request: pytest.FixtureRequest) -> Iterator[UrWorld]:
    """A leased world and its UR address for this test (see the module docstring)."""
    with _leased(request, "armfleet_ur_server") as world:
        headers = {"Authorization": f"Bearer {world.lease.token}"} if world.lease.token else {}
        address = _open_ur_address(world.url, world.world, headers)
        yield UrWorld(world.url, world.world, world.lease, world.client, address)


def _open_ur_address(url: str, world: int, headers: dict[str, str]) -> str:
    """The world's UR address once its ports accept connections: the UR surface opens a lent
    world's ports at its next look at the leases (a fraction of a second), and a ur_rtde
    program connecting before that would be refused."""
    deadline = time.monotonic() + 15
    while True:
        worlds = httpx.get(f"{url}/v1/ur", headers=headers, timeout=10).json()["worlds"]
        mine = next(w for w in worlds if w["world"] == world)
        if mine["open"]:
            return str(mine["address"])
        if time.monotonic() > deadline:
            raise TimeoutError(f"world {world}'s UR ports did not open within 15 s of its lease")
        time.sleep(0.05)
