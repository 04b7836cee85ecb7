"""Large worker replies through shared memory (service/engines/shard_arrays.py), across a real
pipe: arrays come back equal and writable, strided ones included, and blocks do not leak."""

from __future__ import annotations

import multiprocessing as mp
import os

import numpy as np

from service.engines.shard_arrays import ArrayReceiver, ArraySender


def _blocks() -> set[str]:
    return set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()


def test_replies_round_trip_and_a_grown_block_replaces_the_old_one() -> None:
    before = _blocks()
    here, there = mp.Pipe()
    sender, receiver = ArraySender(), ArrayReceiver()
    packed = np.arange(40 * 9, dtype=np.float32).reshape(40, 9)
    small = {"tick": 3, "position": packed[:, 2:5], "faults": np.arange(40)}  # a strided column
    sender.send(here, small)
    got = receiver.recv(there)
    assert got["tick"] == 3
    np.testing.assert_array_equal(got["position"], packed[:, 2:5])
    np.testing.assert_array_equal(got["faults"], np.arange(40))
    got["position"][0, 0] = -1.0  # the caller's own copy
    assert packed[0, 2] == 2.0
    first = receiver._block.name if receiver._block is not None else None
    big = np.random.default_rng(1).standard_normal((1000, 300))
    sender.send(here, (big, "no arrays here"))
    again, text = receiver.recv(there)
    np.testing.assert_array_equal(again, big)
    assert text == "no arrays here" and receiver._block is not None
    assert receiver._block.name != first  # grown: a new block, the old one unlinked
    sender.send(here, {"none": None})
    assert receiver.recv(there) == {"none": None}
    sender.close()
    receiver.close()
    assert _blocks() <= before  # nothing left behind
