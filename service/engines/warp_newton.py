"""MuJoCo Warp's Newton solve on the CPU, with an exit for worlds whose warm start has converged.

Why: MuJoCo Warp's Newton solve builds the Hessian H = M + JᵀDJ, factorizes it and takes at
least one iteration in every world on every step, converged or not. At rest that is most of
what a step's solve costs on the CPU, where Warp kernels run on one core without SIMD: one
512-world shard spent ~18 ms of a ~108 ms tick on the Hessian and its factorization and ~10 ms
on the one iteration (per-kernel thread CPU, 2 substeps per tick). CG tests its first point
before iterating (0.5 · scale · gᵀM⁻¹g below the tolerance: converged, no iteration), and in the
first hundreds of ticks from home, which `armfleet bench` section 19 serves, its worlds mostly
stop there; Newton paid its full price every step (section 19 against the CG tree f667f8e:
0.78x on MuJoCo Warp).

What changes, before the Hessian, per world: CG's own test at Newton's first point (the warm
start). A world that passes is done with the warm start as its solution, like a CG world
converged at its first point. Newton would stop there anyway: H ⪰ M makes its "model
improvement" test (0.5 · scale · gᵀH⁻¹g below the tolerance) weaker than this one, so the
world's Newton step would improve the cost by less than the tolerance. The test needs g and
M⁻¹g: M's factor is the step's own. Worlds still solving take Newton's path as before:
Hessian, factorization, iterations. Measured at rest from home (512 worlds, ticks 0-250,
per-tick alternation, thread CPU): the test passes ~55-80% of steps, ticks 1.07x CG's (Newton
as before 1.25x); with every arm pressed every 0.1 s almost no world passes, and the cost over
Newton as before is the test, ~2% of a tick (128 worlds).

Tried and taken out: a world failing the test by under 100 tolerances first took one CG step
(MuJoCo Warp's linesearch and constraint update along -M⁻¹g) and the test again (1.00x CG's at
rest), but a gripper whose cube's friction was lowered then kept holding the cube where it must
slip out (tests/test_params.py::test_a_lowered_friction_lets_the_held_cube_slip_out_of_the_gripper
failed with it, passes without): a stopped CG step there is not a converged solve.

The rest of the solve is MuJoCo Warp's own, called in the order of its `_solve` (mujoco-warp
4.0.0, pinned in pyproject.toml; `install` leaves any other version alone). Only the CPU, the
continuous integrators and a full (not compacted, not sleeping) solve take the exit; anything
else runs MuJoCo Warp's `_solve` unchanged. The fidelity tests hold with it (warp vs native
MuJoCo and vs mj_step: tests/test_engine.py, tests/test_model.py; bench section 24).
"""

from __future__ import annotations

import logging
from typing import Any

import mujoco_warp
import warp as wp
from mujoco_warp._src import smooth, types
from mujoco_warp._src import solver as mjw_solver

log = logging.getLogger("armfleet.engine")

# The version whose `_solve` the solve below follows step by step.
FOLLOWS = "4.0.0"

_original_solve = mjw_solver._solve


@wp.kernel
def converged_at_start(
    nv: int,
    opt_tolerance: wp.array(dtype=float),
    inertia_scale: wp.array(dtype=float),
    grad: wp.array2d(dtype=float),
    mgrad: wp.array2d(dtype=float),
    done: wp.array(dtype=bool),
    nsolving: wp.array(dtype=int),
):
    """CG's first-point test (mujoco_warp's `_solve_init_search_cg_tiled`, continuous
    integrators): a world whose 0.5 · scale · gᵀM⁻¹g is below the tolerance is done."""
    world = wp.tid()
    if done[world]:
        return
    gap = float(0.0)  # noqa: UP018 (a Warp variable the loop may change, not a constant)
    for dof in range(nv):
        gap += grad[world, dof] * mgrad[world, dof]
    tolerance = opt_tolerance[world % opt_tolerance.shape[0]]
    if wp.max(0.0, 0.5 * inertia_scale[world] * gap) < tolerance:
        done[world] = True
        wp.atomic_sub(nsolving, 0, 1)


def takes_exit(m: types.Model, d: types.Data, compact: bool) -> bool:
    """Whether this solve gets the converged-start exit (see the module doc)."""
    return (
        m.opt.solver == types.SolverType.NEWTON
        and m.opt.integrator != types.IntegratorType.DISCRETE
        and not (m.opt.enableflags & types.EnableBit.SLEEP)
        and not compact
        and m.opt.iterations > 0
        and not smooth.skip_qacc_smooth(m, d)  # M's factor is fresh: the step computed qacc_smooth
        and d.qacc.device.is_cpu
    )


def _stop_converged(
    m: types.Model, d: types.Data, ctx: Any, nsolving: wp.array, mgrad: wp.array
) -> None:
    """The gradient at the warm start, M⁻¹ times it, and the test: converged worlds are done."""
    deterministic = bool(m.opt.deterministic & types.DeterminismType.ATOMICS)
    wp.launch(
        mjw_solver._update_gradient_zero_grad_dot(False),
        dim=d.nworld,
        inputs=[d.nefc, ctx.alpha, ctx.done],
        outputs=[ctx.grad_dot, ctx.newton_decrement, ctx.grad_scale, ctx.search_unchanged],
    )
    wp.launch(
        mjw_solver._update_gradient_grad(False, deterministic),
        dim=(d.nworld, m.nv),
        inputs=[d.qfrc_smooth, d.qfrc_constraint, d.efc.Ma, d.nefc, ctx.done],
        outputs=[ctx.grad, ctx.grad_dot],
    )
    smooth.solve_m(m, d, mgrad, ctx.grad)
    wp.launch(
        converged_at_start,
        dim=d.nworld,
        inputs=[m.nv, m.opt.tolerance, ctx.inertia_scale, ctx.grad, mgrad],
        outputs=[ctx.done, nsolving],
    )


def solve(m: types.Model, d: types.Data, ctx: Any, compact: bool = False) -> None:
    """mujoco_warp's `_solve` (4.0.0), with converged worlds stopped before the Hessian."""
    if not takes_exit(m, d, compact):
        _original_solve(m, d, ctx, compact=compact)
        return
    warmstart = not (m.opt.disableflags & types.DisableBit.WARMSTART)
    wp.launch(
        mjw_solver._solve_init_dof(warmstart, m.is_sparse, True),
        dim=(d.nworld, m.nv),
        inputs=[d.nefc, d.qacc_warmstart, d.qacc_smooth],
        outputs=[d.qacc, d.qfrc_constraint],
    )
    mjw_solver.init_context(m, d, ctx, grad=False, compact=compact)
    nsolving = wp.full(shape=(1,), value=d.nworld, dtype=int)
    mgrad = wp.zeros_like(ctx.grad)  # Newton's context has no Mgrad (CG's)
    _stop_converged(m, d, ctx, nsolving, mgrad)
    # the rest skips done worlds: Hessian, factorization and the iterations
    mjw_solver._update_gradient(m, d, ctx, compact=compact)
    incremental = mjw_solver._use_incremental(m)
    if incremental:
        ctx.search_unchanged.zero_()
    if m.opt.graph_conditional:
        wp.capture_while(
            nsolving,
            while_body=mjw_solver._solver_iteration,
            m=m,
            d=d,
            ctx=ctx,
            nsolving=nsolving,
            compact=compact,
        )
    else:
        for _ in range(m.opt.iterations):
            mjw_solver._solver_iteration(m, d, ctx, nsolving, compact=compact)
    if incremental:
        # a world done at its start has its gradient there and grad_scale 1: this is the
        # qfrc_constraint its constraint update computed
        wp.launch(
            mjw_solver._qfrc_constraint_from_grad,
            dim=(d.nworld, m.nv),
            inputs=[d.qfrc_smooth, d.efc.Ma, ctx.grad, ctx.grad_scale],
            outputs=[d.qfrc_constraint],
        )


def install() -> bool:
    """Put `solve` in mujoco_warp's place (idempotent); False, and nothing changed, on a
    mujoco_warp other than the one it follows."""
    if mjw_solver._solve is solve:
        return True
    if mujoco_warp.__version__ != FOLLOWS:
        log.warning(
            "mujoco_warp %s, not %s: Newton's converged-start exit is off (warp_newton.py)",
            mujoco_warp.__version__,
            FOLLOWS,
        )
        return False
    mjw_solver._solve = solve
    return True
