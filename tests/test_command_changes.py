"""The command table's change count: the clearance watch looks at every world's pending targets
after a tick only when the count moved since its last look (clearance_watch.py says why), so
every way the pending targets can change must move it, and a tick with nothing staged must not
(or the watch would compare all worlds every tick again)."""

from __future__ import annotations

import threading

import numpy as np

from service.core.sim.arithmetic import TargetUpdate
from service.core.sim.command_desk import CommandDesk
from service.core.sim.staging import CommandTable
from tests.conftest import SPEC

N = 4


def _desk() -> CommandDesk:
    table = CommandTable(np.tile(SPEC.home, (N, 1)), SPEC.home)
    return CommandDesk(threading.Lock(), table, N, lambda: 1, lambda: 0)


def _row(target: np.ndarray):
    return lambda world, row: TargetUpdate(target=target.copy(), clamped=[])


def test_every_change_of_the_pending_targets_moves_the_count_and_an_empty_tick_does_not() -> None:
    desk = _desk()
    table = desk.table
    seen = desk.changes
    assert not table.take() and desk.changes == seen  # nothing staged: still

    moved = SPEC.home + 0.1
    desk.stage_rows([2], _row(moved), [0])  # a target command
    assert desk.changes > seen and np.array_equal(desk.pending_targets(2), moved)
    seen = desk.changes
    assert table.take() and desk.changes >= seen
    seen = desk.changes

    desk.reset([2])  # a reset: home again
    assert desk.changes > seen
    table.take()
    seen = desk.changes

    # A trajectory writes its samples through a lent view (`Staging`) and says so (`wrote`),
    # then the tick takes them: the count moves, as does the lending itself (`staging`).
    st = desk.view()
    st.pending[1] = moved
    st.dirty[1] = True
    desk.wrote()
    assert desk.changes > seen
    writes = table.take()
    assert list(writes.worlds) == [1] and np.array_equal(writes.targets[0], moved)
    seen = desk.changes
    assert not table.take() and desk.changes == seen  # taken: nothing left, the count still
    with desk.staging([3]) as st:
        st.pending[3] = moved
    assert desk.changes > seen
    seen = desk.changes

    table.faulted(np.array([3]))  # the engine reset a faulted world: its target is home again
    assert desk.changes > seen and np.array_equal(desk.pending_targets(3), SPEC.home)
    seen = desk.changes

    table.restored(np.tile(moved, (N, 1)), 7)  # a restore replaces every row
    assert desk.changes > seen
    seen = desk.changes
    assert not table.take() and desk.changes == seen  # and quiet again


def test_a_quiet_table_still_hands_every_kind_of_write_to_the_next_take() -> None:
    """`take` skips its scan while the count stands where its last emptying left it: each way
    of staging must still reach the engine (state writes are a list, checked every time)."""
    from service.core.sim.batch import StateWrite

    desk = _desk()
    table = desk.table
    assert not table.take() and not table.take()  # quiet: the scan is skipped
    desk.stage_state([StateWrite("qpos", 1, np.array([0]), np.array([0.2]))])
    assert table.take().state and not table.take()
    desk.reset([0])
    assert list(table.take().resets) == [0] and not table.take()
    desk.stage_rows([3], _row(SPEC.home + 0.05), [0])
    assert list(table.take().worlds) == [3] and not table.take()
