"""Host cost of the loop's per-tick stages at N worlds, CPU seconds per call (issue 39 item 3,
branch gpu7): a micro-benchmark, not product code.

A SimLoop over native MuJoCo at N worlds (never started: the stages are called in turn on this
thread, the engine's step left out), a trajectory manager and the metrics attached as the
service does. Each stage runs REPS times, nothing staged, and the thread CPU time per call is
printed (min and median of BLOCKS blocks). Usage: python stages.py [N] [REPS] [BLOCKS]
"""

from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from service.core.commands.control import Control
from service.core.metrics import Metrics
from service.core.sim.loop import SimLoop
from service.core.sim.settings import SimSettings
from service.core.sim.types import Mode
from service.engines.choice import build_batch
from service.engines.settings import EngineSettings

N = int(sys.argv[1]) if len(sys.argv) > 1 else 16384
REPS = int(sys.argv[2]) if len(sys.argv) > 2 else 2000
BLOCKS = int(sys.argv[3]) if len(sys.argv) > 3 else 7

batch = build_batch(EngineSettings(kind="mujoco", shards=1), SimSettings(worlds=N))
loop = SimLoop(batch, Mode.PAUSED)
control = Control(loop)  # attaches the trajectory manager, as the service
metrics = Metrics()
loop.listeners.add_tick_listener(metrics.on_tick)
faulted = np.zeros(0, dtype=np.int64)
now = time.monotonic()


def take() -> None:
    loop._take_commands()


def finish() -> None:
    loop._finish_tick(faulted, Mode.FAST, now)


def counted() -> None:
    loop.listeners.counted(loop.tick, 0.0036, 0)


def between() -> None:  # the loop's own turn between two ticks (fast mode, nothing waiting)
    loop.priority.follow(False)
    with loop._turns.loop_turn():
        loop._serve_requests()
    with loop._wake:
        loop.share.set_active(False)
    with loop._turns.loop_turn():
        pass
    loop._failures.succeeded()


STAGES = {"take_commands": take, "finish_tick": finish, "counted": counted, "between": between}
out: dict[str, list[float]] = {k: [] for k in STAGES}
for _ in range(BLOCKS):
    for name, fn in STAGES.items():
        t0 = time.thread_time()
        for _ in range(REPS):
            fn()
        out[name].append((time.thread_time() - t0) / REPS * 1e6)
for name, v in out.items():
    mid = statistics.median(v)
    print(f"{name:15s} min {min(v):6.2f} us  median {mid:6.2f} us  (CPU, {N} worlds)")
