"""Where the box's CPU went over a window: the server's own process, its engine workers, this
process (the bench's clients), and everything else on the machine.

Why: a real-time factor alone cannot say whether the ticks lost to the commands, to the
clients sending them (on the same box), or to other work on a shared machine. The ticks' cost
is stated as CPU milliseconds per tick, which the box's load does not change much, beside the
cores each party used (section 31).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import psutil


def _cpu(proc: psutil.Process) -> float:
    try:
        t = proc.cpu_times()
        return t.user + t.system
    except psutil.Error:
        return 0.0


def _busy() -> float:
    t = psutil.cpu_times()
    return t.user + t.nice + t.system + t.irq + t.softirq + getattr(t, "steal", 0.0)


@dataclass
class Reading:
    """CPU seconds used so far by each party, at `wall` (monotonic seconds)."""

    wall: float
    server: float  # the serving process's own threads (event loop, sim thread, a local shard)
    workers: dict[int, float]  # its child processes by pid (engine shards in workers)
    clients: float  # this process
    box: float  # every core of the machine, busy


def read(server_pid: int) -> Reading:
    server = psutil.Process(server_pid)
    try:
        kids = server.children(recursive=True)
    except psutil.Error:
        kids = []
    return Reading(
        time.monotonic(),
        _cpu(server),
        {k.pid: _cpu(k) for k in kids},
        _cpu(psutil.Process()),
        _busy(),
    )


def between(a: Reading, b: Reading, ticks: int) -> dict[str, float | None]:
    """Cores used by each party from `a` to `b` (CPU seconds per wall second), and CPU
    milliseconds per tick of the server with its workers (`ticks` stepped meanwhile)."""
    wall = max(b.wall - a.wall, 1e-9)
    workers = sum(b.workers.get(pid, cpu) - cpu for pid, cpu in a.workers.items())
    server, clients = b.server - a.server, b.clients - a.clients
    others = (b.box - a.box) - server - workers - clients
    return {
        "cores_server": round(server / wall, 3),
        "cores_workers": round(workers / wall, 3),
        "cores_clients": round(clients / wall, 3),
        "cores_others": round(max(others, 0.0) / wall, 3),
        "cores_idle": round(max(psutil.cpu_count() - (b.box - a.box) / wall, 0.0), 3),
        "server_ms_per_tick": round(1e3 * server / ticks, 2) if ticks else None,
        "workers_ms_per_tick": round(1e3 * workers / ticks, 2) if ticks else None,
        "server_s": round(server, 3),
        "workers_s": round(workers, 3),
        "clients_s": round(clients, 3),
        "ticks": ticks,
    }


def per_command(
    idle: dict[str, float | None], load: dict[str, float | None], handled: int, sent: int
) -> dict[str, float | None]:
    """CPU ms per command of the server (what it spent under load beyond its ticks at their
    idle cost; engine work a busy box's caches make dearer counts here too) over the commands
    it answered (`handled`: acked or refused), and of the clients over the commands `sent`."""
    tick_s = ((idle["server_ms_per_tick"] or 0.0) + (idle["workers_ms_per_tick"] or 0.0)) / 1e3
    beyond = (load["server_s"] or 0.0) + (load["workers_s"] or 0.0) - tick_s * (load["ticks"] or 0)
    return {
        "server_ms_per_command": round(1e3 * beyond / handled, 3) if handled else None,
        "clients_ms_per_command": round(1e3 * (load["clients_s"] or 0.0) / sent, 3)
        if sent
        else None,
    }
