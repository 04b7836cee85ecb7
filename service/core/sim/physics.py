"""The physics options every engine shares, so that warp and native MuJoCo step the same system.

Both engines derive their substep from the control rate the same way and set the same solver
options on the MjModel they load; the fidelity tests (warp vs native) and the benchmarks rely on
that. Nothing here imports warp: the native engine and the tests use it without paying for it.
"""

from __future__ import annotations

import mujoco
import numpy as np

# Approximate physics step [s]; the exact one divides the control tick into whole substeps.
# 1/60 s in 2 substeps (8.33 ms) is the largest step at which every fidelity test passes (hold,
# 0.1 rad step response, grasp and lift, warp vs native within 1 mrad over 2 s, 60 s of random
# presses: tests/test_model.py, tests/test_engine.py); one substep per tick drops the cube.
# Measured for issue 13: warp vs native 1.9e-4 rad at 8.33 ms (4.5e-5 at 2.083 ms); against
# 2.083 ms steps the joints differ by at most 2.2 mrad over 2 s of presses (0.75 mrad at
# 4.17 ms). Four times fewer steps per tick: see bench/ for the gain in worlds held real time.
DEFAULT_PHYSICS_DT = 1.0 / 120.0


def tick_timing(control_hz: float, physics_dt: float) -> tuple[int, float]:
    """(substeps per control tick, exact physics step [s]) so that sim time per tick is exact."""
    tick_dt = 1.0 / control_hz
    substeps = max(1, round(tick_dt / physics_dt))
    return substeps, tick_dt / substeps


def configure(mjm: mujoco.MjModel, physics_dt: float) -> None:
    """Set the step and solver options on a model, in place, as every engine runs it.

    Conjugate gradient instead of Newton: ~15-20% less work per step on this model (measured in
    bench/), and every fidelity test (hold, step response, grasp, warp-vs-native) passes.

    Sleeping is cleared: a model with it needs a persistent native batch (its bookkeeping is not
    in the state rows) and the Newton solver on MuJoCo Warp. A scene that asks for it
    (`LoadedRobot.sleep`) sleeps in the native engine only, on the batch's own copy
    (service.engines.native); warp, the camera renderer and the kinematics step every body.
    """
    mjm.opt.timestep = physics_dt
    mjm.opt.solver = mujoco.mjtSolver.mjSOL_CG
    mjm.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)


def feedforward_gain(mjm: mujoco.MjModel, actuator_ids: np.ndarray) -> np.ndarray:
    """kv / kp of each position actuator: the ctrl offset per rad/s of velocity feed-forward.

    A position servo's force is kp (ctrl - q) - kv q̇, so it lags a target moving at speed v by
    kv/kp × v (0.1 s × v on shoulder_pan). Commanding ctrl = q_d + kv/kp × v_d makes the force
    kp (q_d - q) + kv (v_d - q̇): the same servo tracking a velocity too, within the same force
    limits, with nothing in the model changed. 0 where an actuator has no position gain.
    """
    kp = -mjm.actuator_biasprm[actuator_ids, 1]
    kv = -mjm.actuator_biasprm[actuator_ids, 2]
    return np.where(kp > 0, kv / np.where(kp > 0, kp, 1.0), 0.0)
