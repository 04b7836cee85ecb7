"""The private Ray instance of `--ray local`: out of reach of the service's stop signals, and
gone, at once, when the service goes.

`ray.init(address="local")` starts Ray's processes (GCS, raylet, monitors; the raylet starts its
agents and the shard actors' workers) in the serving process's process group. A terminal's
Ctrl-C reaches them all; Ray blocks SIGINT in them, but SIGTERM to the group (a supervisor, `kill
-TERM -PGID`) stops the raylet (it takes SIGTERM even when blocked), its agents are orphaned, and
the shards' actors lose their raylet while the service is still saving their state. Ray gives
the actor workers sessions of their own, not the rest: while the instance starts (`starting`),
every process Ray launches gets a new session, so the service's process group is the service
alone and stopping stays its decision (service/core/process/stopping.py).

Ray's own shutdown stops the processes with SIGTERM and a second's grace each, and its agents,
once the raylet and GCS are gone, linger for a minute or more; the driver also waits up to 5 s to
flush task events nobody will read. The instance is private and its state already saved, so
`stop_local_instance` (called by the serving process once the service has stopped) lets the
driver disconnect while everything still runs, then kills every process of the instance.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from typing import Any

import psutil
import ray
from ray._private import services

# Ray's driver waits up to 5 s at shutdown to flush its task events (one per shard step) to the
# GCS; nobody reads them for a private instance that is going away.
_FLUSH_TIMEOUT = ("RAY_task_events_shutdown_flush_timeout_ms", "500")


@contextlib.contextmanager
def starting() -> Iterator[None]:
    """Around `connect`: every process Ray starts meanwhile gets a session of its own."""
    os.environ.setdefault(*_FLUSH_TIMEOUT)
    launcher = getattr(services, "ConsolePopen", None)
    if launcher is None:  # another Ray: its processes stay in our group (SIGINT still blocked)
        yield
        return

    class OwnSession(launcher):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            kwargs.setdefault("start_new_session", True)
            super().__init__(*args, **kwargs)

    services.ConsolePopen = OwnSession
    try:
        yield
    finally:
        services.ConsolePopen = launcher


def _sessions(node: Any) -> set[int]:
    """The sessions of the processes the node started (each leads its own, see `starting`);
    the raylet's agents are in the raylet's session, even once the raylet is gone."""
    out = set()
    for infos in node.all_processes.values():
        for info in infos:
            with contextlib.suppress(OSError):
                out.add(os.getsid(info.process.pid))
    out.discard(os.getsid(0))  # never this service's own session (a Ray without `starting`)
    return out


def _kill_sessions(sessions: set[int]) -> None:
    for proc in psutil.process_iter():
        with contextlib.suppress(OSError, psutil.Error):
            if os.getsid(proc.pid) in sessions:
                proc.kill()


def _own_node() -> Any:
    """The node of the local instance this process started, or None (none, or not ours)."""
    node = getattr(ray._private.worker, "_global_node", None)
    return node if node is not None and node.is_head() else None


def kill_local_instance() -> None:
    """Kill the local instance's processes now, without disconnecting (a second Ctrl-C)."""
    node = _own_node()
    if node is not None:
        _kill_sessions(_sessions(node))


def stop_local_instance() -> None:
    """Disconnect from, and kill, the local instance this process started (if it did)."""
    node = _own_node()
    if node is None:
        return  # no instance, or a cluster someone else runs: not ours to stop
    sessions = _sessions(node)
    kill_all = node.kill_all_processes

    def at_once(
        check_alive: bool = False, allow_graceful: bool = False, wait: bool = False
    ) -> None:
        kill_all(check_alive=check_alive, allow_graceful=False, wait=wait)

    node.kill_all_processes = at_once  # no grace: their state is saved, the instance is ours
    with contextlib.suppress(Exception):
        ray.shutdown()
    _kill_sessions(sessions)
