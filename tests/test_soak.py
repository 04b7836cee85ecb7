"""Load with nothing lost, the CI version of `armfleet bench --section 14` (bench/soak.py).

30 s of 48 WebSocket clients on 16 worlds sending ±0.01 increments with ids at ~5/s each: every
command answered exactly once and in order (acked, or refused naming a limit when the box is
too loaded for the command budget), every world's final target exactly home + the sum of
its acked deltas, server memory growth within 64 MB. (The bench runs 200 clients on 64 worlds for
10 minutes; on the 2-core CI machine that would take the whole machine for the whole suite.)
"""

from __future__ import annotations

import asyncio

from conftest import running_server

from bench.soak import soak, table


def test_thirty_seconds_of_many_clients_lose_nothing(tmp_path):
    with running_server(tmp_path, worlds=16) as srv:
        result = asyncio.run(
            soak(srv.url, clients=48, worlds=16, duration=30, server_pid=srv.process.pid)
        )
    print(table(result))
    assert result.problems == []
    assert result.commands_sent > 48 * 30 * 2  # ~5/s each was really sent
    # Every command answered once: acked, or refused naming a limit (the ticks-first budget
    # refuses what waited too long on a loaded box: answered, not lost); nothing else.
    assert result.acks + result.refused == result.commands_sent
    assert result.errors == result.refused and result.acks > result.commands_sent // 2
