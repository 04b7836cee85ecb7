"""PinnedPool (service/engines/warp_frames.py): host copies of device arrays of any dtype, each
buffer reused only once no view of it is left. Run on Warp's CPU device (the same code path as
on a GPU, with pageable buffers)."""

from __future__ import annotations

import numpy as np
import warp as wp

from service.core.sim.device_turns import DeviceTurns
from service.engines.warp_frames import PinnedPool


def test_arrays_of_one_shape_and_other_dtypes_get_buffers_of_their_own() -> None:
    cpu = wp.get_device("cpu")
    counts = wp.array(np.array([[3], [-7]], dtype=np.int32), device=cpu)
    values = wp.array(np.array([[0.5], [2.25]], dtype=np.float32), device=cpu)
    pool = PinnedPool(DeviceTurns())
    got_counts, got_values = pool.copy_out((counts, values), cpu)
    assert got_counts.dtype == np.int32 and got_counts.tolist() == [[3], [-7]]
    assert got_values.dtype == np.float32 and got_values.tolist() == [[0.5], [2.25]]


def test_a_buffer_is_reused_only_once_no_view_of_it_is_left() -> None:
    cpu = wp.get_device("cpu")
    arr = wp.array(np.arange(4, dtype=np.float32), device=cpu)
    pool = PinnedPool()
    first = pool.copy_out((arr,), cpu)[0]
    arr.assign(np.full(4, 9.0, dtype=np.float32))
    second = pool.copy_out((arr,), cpu)[0]
    assert first.tolist() == [0.0, 1.0, 2.0, 3.0]  # held: the second copy took another buffer
    assert second.tolist() == [9.0] * 4
    kept = np.shares_memory(first, second)
    del first
    third = pool.copy_out((arr,), cpu)[0]
    assert not kept and third.tolist() == [9.0] * 4
