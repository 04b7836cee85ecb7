"""The limit `armfleet capacity` states every answer against: raw rollout, read beside each run.

The limit is raw ``mujoco.rollout`` of the served model (the native engine's solver and step)
on every core, as worlds at 60 Hz: world-steps/s over the world-steps one world needs a second
(60 ticks x 2 physics steps = 120). The service counts in the same unit (ticks x worlds x
substeps), so a ratio of the two compares like with like.

Why it is read beside each run and not once: the command used to read it once, at its start
(best of three 1 s blocks), and then measured the engines for three minutes. On a shared
machine the speed available drifts by several percent within a minute (other processes, the
host's other guests), so the limit and the answers compared two different machines: the quiet
run read 52k world-steps/s at its start while section 19 served 57k minutes later. Here the
rollout stays built for the whole command and a short block runs before every server start
(nothing else of ours runs then), so the limit is sampled across the same minute as the
answers; the limit is the best block (the machine at its least disturbed, as an answer is the
most worlds held), and each run also keeps the block read just before it.

What did not explain the low reading (interleaved blocks, CPU time per world-step, one
thread, 256 worlds): starting from settled worlds instead of `home`, carrying the solver's
warm start into each call, and calls of 10 or 120 steps all cost the same within 1% (the
Newton solver needs under one iteration a step here, cold or warm); nor the units (both sides
count world-steps: ticks x worlds x 2 substeps). The engine itself costs the CPU rollout does
per world-step (384 worlds, 2 threads: 34.3k against 33.6k world-steps per CPU second,
medians of interleaved blocks). On a loaded box the thread count tells too: the scheduler
shares the cores per thread, and a served batch (two stepping threads, the frame thread, the
event loop) out-drew the rollout's two threads in some interleaved rounds at load 13.
"""

from __future__ import annotations

import time
from typing import Any

from bench import common

LIMIT_WORLDS = 1024  # batch size at which raw rollout is timed (bench/capacity.py's)
CALL_S = 0.025  # a rollout call at the reference 1e5 steps/s a thread: ~0.1 s on a 2-core box


class RolloutLimit:
    """Raw rollout kept ready for the whole command; `read` times one block of it."""

    def __init__(self, block_s: float) -> None:
        import mujoco

        from bench.baselines import Rollout, physics_dt

        _, dt = physics_dt()
        self.block_s = block_s
        self.steps_per_world_s = common.CONTROL_HZ * round(1 / (common.CONTROL_HZ * dt))
        self.threads = common.usable_cores()
        self.dt = dt
        self._rollout = Rollout(LIMIT_WORLDS, self.threads, dt, target_call_s=CALL_S)
        solver = mujoco.mjtSolver(int(self._rollout.mjm.opt.solver)).name
        self.solver = solver.removeprefix("mjSOL_").lower()
        self.readings: list[dict[str, Any]] = []  # every block, in order, with what it preceded
        self._rollout.block(block_s)  # warm: the pool's threads, the worlds' first steps

    def read(self, before: str) -> float:
        """One block now, `before` saying what runs next; world-steps/s."""
        rate = self._rollout.block(self.block_s, warm=False)
        self.readings.append({"before": before, "t": time.time(), "world_steps_per_s": rate})
        return rate

    def worlds(self, rate: float | None = None) -> float:
        """Worlds at 60 Hz that `rate` (default: the best block so far) steps."""
        return (rate if rate is not None else self.best) / self.steps_per_world_s

    @property
    def best(self) -> float:
        return max(r["world_steps_per_s"] for r in self.readings)

    def summary(self) -> dict[str, Any]:
        """The limit as the result file keeps it."""
        rates = [r["world_steps_per_s"] for r in self.readings]
        return {
            "threads": self.threads,
            "batch": LIMIT_WORLDS,
            "solver": self.solver,
            "physics_dt": self.dt,
            "block_s": self.block_s,
            "world_steps_per_s": self.best,
            "world_steps_per_s_blocks": rates,
            "spread": (max(rates) - min(rates)) / max(rates),
            "readings": self.readings,
            "worlds": self.worlds(),
            "steps_per_world_s": self.steps_per_world_s,
        }

    def close(self) -> None:
        self._rollout.close()
