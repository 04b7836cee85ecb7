"""Section 24: MuJoCo Warp, Newton against CG: the engine's tick and its fidelity, one run.

Why: the solver is chosen by measurement per engine and device, with the fidelity tests as the
bar (service/core/sim/physics.py, ``ENGINE_SOLVER``). Section 20 does it for native MuJoCo's
rollout; this one for the warp engine on the run's device (``--device cuda``: the GPU).

Speed, at every size: one WorldBatch per solver, each settled from home (section 1's
``SETTLE_TICKS``), then blocks of the same number of ticks alternate between them, so that both
meet the same moments of the device and step the same simulated window: first with the home
controls held (what sections 1 and 7 measure), then with a ±0.1 rad press on a random joint of
every world every 0.1 s (arms moving: the CPU showed CG's iterations, and a batch waits for its
slowest world, growing with motion). Best and median world-steps/s of each, the iterations the
last step took (mean over the worlds and the slowest world's) and the faults.

Fidelity, per solver, on the same device (what tests/test_engine.py checks on the CPU): 4
worlds, each a press every 0.1 s, ``FIDELITY_TICKS`` ticks, against (a) float64 ``mj_step`` on
one MjData per world with the same solver and step and (b) the native engine (NativeBatch, its
own solver) through the same Batch calls. The tests' bar: 1 mrad over the first 2 s.

Standalone:
``python -m bench.warp_solvers --section 24 --device cuda --worlds 16384 --worlds 65536``.
"""

from __future__ import annotations

import gc
import statistics
import time
from typing import Any

import numpy as np

from bench.registry import Context, Result, section
from bench.throughput import SETTLE_TICKS

SOLVERS = ("newton", "cg")
PRESS_EVERY = 6  # ticks: 0.1 s at 60 Hz, as the tests press
FIDELITY_WORLDS = 4
FIDELITY_TICKS = 300  # 5 s
BAR_TICKS = 120  # the tests' 2 s
BAR_RAD = 1e-3


def _kind(name: str) -> Any:
    import mujoco

    return getattr(mujoco.mjtSolver, f"mjSOL_{name.upper()}")


class Presses:
    """A ±0.1 rad press on a random joint of every world every `PRESS_EVERY` ticks, within the
    joint limits; the same sequence for every batch given the same seed."""

    def __init__(self, batch: Any, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.worlds = np.arange(batch.nworld)
        self.targets = np.tile(batch.home_target, (batch.nworld, 1))
        self.lo, self.hi = batch.spec.lower, batch.spec.upper

    def next(self) -> np.ndarray:
        n = self.worlds.size
        joints = self.rng.integers(self.targets.shape[1], size=n)
        self.targets[self.worlds, joints] += self.rng.choice([-0.1, 0.1], size=n)
        np.clip(self.targets, self.lo, self.hi, out=self.targets)
        return self.targets


def _block(batch: Any, ticks: int, presses: Presses | None) -> float:
    """World-steps/s over `ticks` ticks (each tick reads the fault count: timed to completion)."""
    t0 = time.perf_counter()
    for k in range(ticks):
        if presses is not None and k % PRESS_EVERY == 0:
            batch.apply_targets(presses.worlds, presses.next())
        batch.step(1)
    return ticks * batch.substeps * batch.nworld / (time.perf_counter() - t0)


def _iterations(batch: Any) -> dict[str, float]:
    niter = batch._d.solver_niter.numpy()  # the last substep's, per world
    return {"mean": float(niter.mean()), "max": int(niter.max())}


def speed(n: int, device: str, rounds: int, block_s: float) -> dict[str, Any]:
    """Both solvers at `n` worlds: blocks at rest, then with presses; see the module doc."""
    from service.engines.warp import WorldBatch

    batches: dict[str, Any] = {}
    tick_s: dict[str, float] = {}
    out: dict[str, Any] = {"nworld": n, "build_s": {}, "settle_ticks": SETTLE_TICKS}
    try:
        for name in SOLVERS:
            t0 = time.perf_counter()
            batches[name] = b = WorldBatch(n, device=device, solver=_kind(name))
            out["build_s"][name] = time.perf_counter() - t0
            t0 = time.perf_counter()
            b.step(SETTLE_TICKS)
            tick_s[name] = (time.perf_counter() - t0) / SETTLE_TICKS
        ticks = max(PRESS_EVERY, round(block_s / max(tick_s.values()) / PRESS_EVERY) * PRESS_EVERY)
        out["block_ticks"] = ticks
        for load in ("rest", "presses"):
            presses = {name: Presses(b, seed=5) for name, b in batches.items()}
            blocks: dict[str, list[float]] = {name: [] for name in SOLVERS}
            for r in range(rounds):
                for name in SOLVERS if r % 2 == 0 else SOLVERS[::-1]:
                    got = _block(batches[name], ticks, presses[name] if load == "presses" else None)
                    blocks[name].append(got)
            out[load] = {
                name: {
                    "blocks": v,
                    "best": max(v),
                    "median": statistics.median(v),
                    "iterations": _iterations(batches[name]),
                }
                for name, v in blocks.items()
            }
        out["faults"] = {name: int(b.snapshot().faults.sum()) for name, b in batches.items()}
    finally:
        batches.clear()
        gc.collect()
    return out


def fidelity(device: str, name: str) -> dict[str, Any]:
    """Worst joint difference [rad] of the warp engine with `name` against mj_step and native."""
    import mujoco

    from service.engines.native import NativeBatch
    from service.engines.warp import WorldBatch

    warp = WorldBatch(FIDELITY_WORLDS, device=device, solver=_kind(name))
    native = NativeBatch(FIDELITY_WORLDS)
    try:
        mjm = warp.robot.mjm  # configured as the batch steps it: this solver, the engine's step
        datas = [mujoco.MjData(mjm) for _ in range(FIDELITY_WORLDS)]
        for d in datas:
            mujoco.mj_resetDataKeyframe(mjm, d, warp.robot.home_key)
        presses = Presses(warp, seed=11)
        adr = warp.robot.qpos_adr
        vs_step = np.zeros(FIDELITY_TICKS)
        vs_native = np.zeros(FIDELITY_TICKS)
        for tick in range(FIDELITY_TICKS):
            if tick % PRESS_EVERY == 0:
                targets = presses.next()
                for b in (warp, native):
                    b.apply_targets(presses.worlds, targets)
                for d, t in zip(datas, targets, strict=True):
                    d.ctrl[:] = t
            warp.step(1)
            native.step(1)
            for d in datas:
                mujoco.mj_step(mjm, d, nstep=warp.substeps)
            q = warp.snapshot().position
            vs_step[tick] = np.abs(q - np.stack([d.qpos[adr] for d in datas])).max()
            vs_native[tick] = np.abs(q - native.snapshot().position).max()
        faults = int(warp.snapshot().faults.sum())
    finally:
        native.close()
    bar_step, bar_native = float(vs_step[:BAR_TICKS].max()), float(vs_native[:BAR_TICKS].max())
    return {
        "vs_mj_step_2s_rad": bar_step,
        "vs_native_2s_rad": bar_native,
        "vs_mj_step_rad": float(vs_step.max()),
        "vs_native_rad": float(vs_native.max()),
        "native_solver": int(native.robot.mjm.opt.solver),
        "faults": faults,
        "passes": bar_step < BAR_RAD and bar_native < BAR_RAD and faults == 0,
    }


@section(24, "warp_solvers", ("cpu", "cuda"), default_on=())
def warp_solvers(ctx: Context) -> Result:
    """MuJoCo Warp: Newton vs CG, the engine's tick and its fidelity, one run"""
    sizes = ctx.sizes(
        (16384, 65536) if ctx.cuda else (64, 256), quick=(16384,) if ctx.cuda else (64,)
    )
    rounds, block_s = ctx.pick((4, 2.0), (2, 0.5))
    fid: dict[str, dict[str, Any]] = {}
    errors: dict[str, str] = {}
    for name in SOLVERS:
        try:
            fid[name] = fidelity(ctx.device, name)
        except Exception as exc:  # one failing must not lose the speed figures
            errors[f"fidelity/{name}"] = f"{type(exc).__name__}: {exc}"
        ctx.say(f"  fidelity {name}: {fid.get(name) or errors[f'fidelity/{name}']}")

    def describe(r: dict[str, Any]) -> str:
        return ", ".join(
            f"{load} {k} {r[load][k]['median']:,.0f}"
            for load in ("rest", "presses")
            for k in SOLVERS
        )

    results, size_errors = ctx.each(
        sizes, lambda n: speed(n, ctx.device, rounds, block_s), describe
    )
    errors |= size_errors
    rows = []
    for n, r in results.items():
        for name in SOLVERS:
            row: dict[str, Any] = {"worlds": int(n), "solver": name}
            for load in ("rest", "presses"):
                got, cg = r[load][name], r[load]["cg"]
                row[f"{load}: median world-steps/s"] = got["median"]
                row[f"{load}: / CG"] = got["median"] / cg["median"]
                row[f"{load}: iterations mean/max"] = (
                    f"{got['iterations']['mean']:.1f}/{got['iterations']['max']}"
                )
            f = fid.get(name, {})
            row["vs mj_step 2 s, mrad"] = 1e3 * f["vs_mj_step_2s_rad"] if f else None
            row["vs native 2 s, mrad"] = 1e3 * f["vs_native_2s_rad"] if f else None
            rows.append(row)
    data = {
        "rounds": rounds,
        "block_s": block_s,
        "press_every_ticks": PRESS_EVERY,
        "fidelity": fid,
        "fidelity_worlds": FIDELITY_WORLDS,
        "fidelity_ticks": FIDELITY_TICKS,
        "bar": {"ticks": BAR_TICKS, "rad": BAR_RAD},
        "results": results,
        "errors": errors,
    }
    notes = [
        f"fidelity {name}: {'passes' if f['passes'] else 'FAILS'} the tests' bar "
        f"(1 mrad over 2 s vs mj_step and vs native; over 5 s: "
        f"{1e3 * f['vs_mj_step_rad']:.3f} / {1e3 * f['vs_native_rad']:.3f} mrad)"
        for name, f in fid.items()
    ]
    return Result(rows, data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
