"""The physics options every engine shares, so that warp and native MuJoCo step the same system.

Both engines derive their substep from the control rate the same way and set the same solver
options on the MjModel they load; the fidelity tests (warp vs native) and the benchmarks rely on
that. Nothing here imports warp: the native engine and the tests use it without paying for it.
"""

from __future__ import annotations

import mujoco

# Approximate physics step [s]; the exact one divides the control tick into whole substeps.
# 1/60 s in 8 substeps (2.083 ms) is what every fidelity test passes at (tests/test_model.py,
# tests/test_engine.py); see bench/ for the measured cost per step.
DEFAULT_PHYSICS_DT = 0.002


def tick_timing(control_hz: float, physics_dt: float) -> tuple[int, float]:
    """(substeps per control tick, exact physics step [s]) so that sim time per tick is exact."""
    tick_dt = 1.0 / control_hz
    substeps = max(1, round(tick_dt / physics_dt))
    return substeps, tick_dt / substeps


def configure(mjm: mujoco.MjModel, physics_dt: float) -> None:
    """Set the step and solver options on a model, in place, as every engine runs it.

    Conjugate gradient instead of Newton: ~15-20% less work per step on this model (measured in
    bench/), and every fidelity test (hold, step response, grasp, warp-vs-native) passes.
    """
    mjm.opt.timestep = physics_dt
    mjm.opt.solver = mujoco.mjtSolver.mjSOL_CG
