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

      def test_elbow_moves(armfleet_world):
          arm, w = armfleet_world.client, armfleet_world.world
          arm.increment(w, "elbow_joint", 0.1)
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from typing import Any

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


@pytest.fixture
def armfleet_world(request: pytest.FixtureRequest) -> Iterator[LeasedWorld]:
    """A leased world of its own for this test (see the module docstring)."""
    url = os.environ.get("ARMFLEET_URL")
    if not url:
        url = request.getfixturevalue("armfleet_lending_server").url
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    label = f"pytest {worker} {request.node.nodeid}"[:120]
    with lease_world(url, os.environ.get("ARMFLEET_TOKEN"), label) as world:
        yield world
