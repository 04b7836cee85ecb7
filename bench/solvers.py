"""Section 20: Newton against CG for native MuJoCo, raw rollout of the served model, one run.

Why: the solver is chosen by measurement on the model as served (service/core/sim/physics.py,
``ENGINE_SOLVER``), and the faster one differs by CPU (Newton was 10% faster on an AMD EPYC, the
same within the noise on an Intel Xeon). Blocks of ``mujoco.rollout`` on every core alternate
between the two solvers, each block continuing from the same settled state, so that both meet
the same moments of a shared machine; best and median of each, and the iterations a step takes.

Standalone: ``python -m bench.solvers --section 20``.
"""

from __future__ import annotations

import statistics
from typing import Any

from bench import common
from bench.registry import Context, Result, section

SOLVERS = ("newton", "cg")


def _iterations(mjm: Any, state: Any, steps: int = 120) -> float:
    """Mean solver iterations a step over `steps` steps from `state` (one world, serial)."""
    import mujoco

    data = mujoco.MjData(mjm)
    mujoco.mj_setState(mjm, data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    total = 0
    for _ in range(steps):
        mujoco.mj_step(mjm, data)
        total += int(data.solver_niter[0])
    return total / steps


@section(20, "solvers", default_on=())
def solvers(ctx: Context) -> Result:
    """Native MuJoCo: Newton vs CG, raw rollout on every core, one run"""
    import mujoco

    from bench.baselines import Rollout, physics_dt

    nworld = (ctx.worlds or [1024])[0]
    rounds, block_s = ctx.pick((6, 1.0), (2, 0.3))
    _, dt = physics_dt()
    rollout = Rollout(nworld, common.usable_cores(), dt)
    kinds = {name: getattr(mujoco.mjtSolver, f"mjSOL_{name.upper()}") for name in SOLVERS}
    blocks: dict[str, list[float]] = {name: [] for name in SOLVERS}
    iterations: dict[str, float] = {}
    try:
        rollout.block(block_s)  # the worlds settle from home: every block starts from here
        settled = rollout.initial.copy()
        for r in range(rounds):
            for name in SOLVERS if r % 2 == 0 else SOLVERS[::-1]:
                rollout.mjm.opt.solver = kinds[name]
                rollout.initial[:] = settled
                blocks[name].append(rollout.block(block_s))
        for name in SOLVERS:
            rollout.mjm.opt.solver = kinds[name]
            iterations[name] = _iterations(rollout.mjm, settled[0])
    finally:
        rollout.close()
    best = {k: max(v) for k, v in blocks.items()}
    median = {k: statistics.median(v) for k, v in blocks.items()}
    rows = [
        {
            "solver": name,
            "best world-steps/s": best[name],
            "median world-steps/s": median[name],
            "best / CG": best[name] / best["cg"],
            "median / CG": median[name] / median["cg"],
            "iterations a step": iterations[name],
        }
        for name in SOLVERS
    ]
    data = {
        "nworld": nworld,
        "threads": common.usable_cores(),
        "physics_dt": dt,
        "rounds": rounds,
        "block_s": block_s,
        "blocks": blocks,
        "iterations": iterations,
    }
    faster = max(SOLVERS, key=lambda k: median[k])
    notes = [f"faster by the median of interleaved blocks here: {faster}"]
    return Result(rows, data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
