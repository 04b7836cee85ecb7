"""On the device: the beside snapshot equals the plain one of its tick at 65,536 worlds, and what
each costs the sim thread (host ms per call); run from the tree under test."""

import sys
import time

import numpy as np

from service.engines.warp import WorldBatch

n = int(sys.argv[1]) if len(sys.argv) > 1 else 65536
b = WorldBatch(n, device="cuda:0")
b.step(30)
got = b.snapshot_beside()
assert got is not None, "no beside copy on CUDA"
snap, wait = got
ref = b.snapshot()
b.step(3)
wait()
for name in ("sim_time", "position", "velocity", "effort", "faults", "flange_pos", "body_pos"):
    assert np.array_equal(getattr(snap, name), getattr(ref, name)), name
print(f"beside snapshot equals the plain one at tick {snap.tick} ({n} worlds)")
del snap, ref, got


def per_call(fn, reps=20):
    t = []
    for _ in range(reps):
        b.step(1)
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(t))


def start_only():
    t0 = time.perf_counter()
    _snap, w = b.snapshot_beside()
    dt = time.perf_counter() - t0
    w()  # as the loop does after the next tick (here at once, to free the buffer)
    return dt


plain = per_call(lambda: b.snapshot())
starts = []
for _ in range(20):
    b.step(1)
    starts.append(start_only())
beside = 1e3 * np.median(starts)
print(f"sim thread ms per snapshot: plain {plain:.3f}, beside (start) {beside:.3f}")
