"""The physics options every engine shares, so that warp and native MuJoCo step the same system.

Both engines derive their substep from the control rate the same way and set their solver on
the MjModel they load (`ENGINE_SOLVER`: each engine's faster one on the served model, with every
fidelity test passing); the fidelity tests (warp vs native) and the benchmarks rely on that.
Nothing here imports warp: the native engine and the tests use it without paying for it.
"""

from __future__ import annotations

from dataclasses import dataclass

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

# The constraint solver each engine steps the served model with, chosen by measurement (issue 39;
# docs/performance.md, "The solver"). Native MuJoCo: Newton converges in 1-2 iterations where CG
# takes ~10 (up to ~50 while the worlds settle), and a step costs 5% fewer instructions (callgrind,
# 240 steps from home: 42.2M vs 44.6M); raw rollout on both cores of a 2-core Xeon stepped 8-19%
# more (best blocks, bench section 20), 10% on a 2-core AMD EPYC. MuJoCo Warp on the CPU: Newton
# too. CG was ~20% cheaper with every arm at rest, but a batch iterates until its last world
# converges, and while arms move CG hits its 100-iteration limit: one 32-world shard tick cost 12.6
# ms of CPU with 1 arm moving, 18.6 with 16 and 24.5 with 32, against 5.6-7.2 at rest; Newton
# 7.0-7.3 ms in every case (2-core Xeon, issue 39 item 4: the 200-client soak moved the arms, and
# the engine alone then needed more than the box's two cores). The price, at rest in large shards:
# one 512-world shard (the service at 1,024 worlds on two cores) ticks in 99.6 ms of CPU with Newton
# against 77.8 with CG (1.28x; captured ticks, best of 5 alternating blocks, load 0.1-0.9), which
# was section 19's MuJoCo Warp ratio against the CG tree f667f8e (0.857); service/engines/
# warp_newton.py now stops converged worlds before the Hessian (1.07x CG's tick at rest; section 19
# docs/performance.md). Moving, a 32-world shard: Newton 8.5 ms, CG 36.6 (capped at 20 or 30
# iterations still 15.2 or 20.7 ms);
# every arm of a 512-world shard retargeted every 0.5 s: Newton 158 ms, CG 834 (load 10-30), so no
# shard size makes CG the better default. No MuJoCo Warp 4.0 option narrows the rest gap (512
# worlds, load 14-30): run_qacc_smooth=False 102.2 vs 101.8 ms, a sparse Jacobian 118.5,
# ls_iterations=10 with ls_tolerance=0.1 107.1 vs 107.0; nor does batching every writable Model
# field per world (99.9 vs 99.6 ms, CG 77.7 vs 77.8). MuJoCo Warp on CUDA ("warp_cuda"): Newton too,
# by bench section 24 on one H200 (bench/results/issue39/gpu4): the engine's tick at rest 2.6x CG's
# world-steps/s at 16,384 worlds (9.86M vs 3.79M) and 2.9x at 65,536 (12.3M vs 4.26M); with a press
# every 0.1 s in every world 7.9x and 7.6x (5.52M vs 0.70M, 7.24M vs 0.96M): a step takes 1
# iteration (the slowest world 14), where CG takes 3 at rest (slowest 23-31) and 33 under presses
# with worlds at its 100-iteration limit, which the whole batch waits for (and MuJoCo Warp prints a
# warning per world and step that hits it). Against float64 mj_step over 2 s of presses Newton is
# off by 0.008 mrad, CG by 0.18. Every fidelity test passes with these (tests/test_model.py,
# tests/test_engine.py warp vs native, tests/test_native.py, tests/test_params.py,
# tests/test_batch_contract.py).
ENGINE_SOLVER = {
    "mujoco": mujoco.mjtSolver.mjSOL_NEWTON,
    "warp": mujoco.mjtSolver.mjSOL_NEWTON,
    "warp_cuda": mujoco.mjtSolver.mjSOL_NEWTON,
}


def warp_solver(cuda: bool) -> mujoco.mjtSolver:
    """MuJoCo Warp's solver on a CUDA device (`cuda`) or on the CPU (`ENGINE_SOLVER`)."""
    return ENGINE_SOLVER["warp_cuda" if cuda else "warp"]


def solver_name(mjm: mujoco.MjModel) -> str:
    """The model's solver as MJCF spells it: 'newton', 'cg', 'pgs'."""
    return mujoco.mjtSolver(int(mjm.opt.solver)).name.removeprefix("mjSOL_").lower()


# A cell that sets this custom numeric to 1 is stepped with its own <option> timestep and solver
# (issue 38: a tuned cell must not get other physics without a word): `own_physics`.
KEEP_OWN = "armfleet_own_physics"


@dataclass(frozen=True)
class CellPhysics:
    """A cell's own step options, as written in its MJCF (read before `configure` replaces
    them): timestep [s], solver and integrator names as MJCF spells them, and whether the
    cell asks to keep them (the custom numeric `armfleet_own_physics` = 1)."""

    timestep: float
    solver: str
    integrator: str
    keep: bool

    @classmethod
    def of(cls, mjm: mujoco.MjModel) -> CellPhysics:
        keep = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_NUMERIC, KEEP_OWN)
        return cls(
            float(mjm.opt.timestep),
            solver_name(mjm),
            mujoco.mjtIntegrator(int(mjm.opt.integrator)).name.removeprefix("mjINT_").lower(),
            keep >= 0 and bool(mjm.numeric_data[mjm.numeric_adr[keep]]),
        )

    def step(self, physics_dt: float) -> float:
        """The approximate physics step to use: the cell's own when it keeps it."""
        return self.timestep if self.keep else physics_dt

    def told(self, control_hz: float, physics_dt: float, solver: str = "cg") -> str | None:
        """The one line `serve` logs at start about the cell's step options (None: nothing was
        replaced and the step is the cell's): what was replaced and how to keep the cell's own,
        or, when kept, that a timestep not dividing the control tick was rounded. `solver`:
        the one the engine steps with (`solver_name` of the configured model)."""
        substeps, exact = tick_timing(control_hz, self.step(physics_dt))
        how = f"{substeps} substeps of {exact * 1e3:.4g} ms per 1/{control_hz:g} s tick"
        if self.keep:
            if abs(exact - self.timestep) <= 1e-12 * max(1.0, self.timestep):
                return None
            return (
                f"physics: the cell's timestep {self.timestep * 1e3:.4g} ms does not divide the "
                f"1/{control_hz:g} s control tick: stepping {how} (its {self.solver} solver and "
                f"{self.integrator} integrator kept)"
            )
        replaced = []
        if abs(exact - self.timestep) > 1e-12:
            replaced.append(f"timestep {self.timestep * 1e3:.4g} ms")
        if self.solver != solver:
            replaced.append(f"{self.solver} solver")
        if not replaced:
            return None
        ours = "CG" if solver == "cg" else solver.capitalize()
        return (
            f"physics: the cell's {' and '.join(replaced)} replaced by armfleet's: {how}, "
            f"{ours} solver (its {self.integrator} integrator kept); to keep the cell's own, add "
            f'<custom><numeric name="{KEEP_OWN}" data="1"/></custom> to it'
        )


def tick_timing(control_hz: float, physics_dt: float) -> tuple[int, float]:
    """(substeps per control tick, exact physics step [s]) so that sim time per tick is exact."""
    tick_dt = 1.0 / control_hz
    substeps = max(1, round(tick_dt / physics_dt))
    return substeps, tick_dt / substeps


def configure(
    mjm: mujoco.MjModel,
    physics_dt: float,
    solver: mujoco.mjtSolver = ENGINE_SOLVER["warp"],
) -> None:
    """Set the step and solver options on a model, in place, as an engine runs it.

    `solver`: the engine's (`ENGINE_SOLVER`). A cell that keeps its own physics
    (`CellPhysics.keep`) keeps its solver; the step is the exact one the engine derived from
    its timestep (`tick_timing`).

    Sleeping is cleared: a model with it needs a persistent native batch (its bookkeeping is not
    in the state rows) and the Newton solver on MuJoCo Warp. A scene that asks for it
    (`LoadedRobot.sleep`) sleeps in the native engine only, on the batch's own copy
    (service.engines.native); warp, the camera renderer and the kinematics step every body.
    """
    keep = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_NUMERIC, KEEP_OWN)
    mjm.opt.timestep = physics_dt
    if keep < 0 or not mjm.numeric_data[mjm.numeric_adr[keep]]:
        mjm.opt.solver = solver
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
