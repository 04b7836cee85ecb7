"""What the engine is measured against, outside the service: raw MuJoCo Warp and native
MuJoCo's `mujoco.rollout`, on the robot model exactly as the engines configure it.

Why a module of its own: sections 1, 10, 11, 20, 21 and the capacity command all compare
with these baselines; building them the same way everywhere keeps their figures comparable
(the same model, step, solver and starting state). Heavy packages are imported inside the
functions (the bench imports every module to find its sections).
"""

from __future__ import annotations

import math
from typing import Any

from bench import common


def physics_dt() -> tuple[int, float]:
    """(substeps, physics_dt) of the engine's defaults, exactly as WorldBatch derives them."""
    from service.core.sim.physics import tick_timing

    return tick_timing(common.CONTROL_HZ, common.PHYSICS_DT)


def engine_model(device: str = "cpu", engine: str = "mujoco") -> tuple[Any, int]:
    """(MjModel, home key id) configured exactly as `engine` configures its own (its solver).

    Both engines load the robot and set their options with `service.core.sim.physics.configure` at
    the default step: doing the same here keeps the baselines on the same physics whatever the
    engine changes, without building (and on a GPU run compiling CPU kernels for) a batch.
    `device` is accepted for the callers' symmetry; the model is host data. A fresh model each
    call.
    """
    from service.core.sim.physics import ENGINE_SOLVER, configure
    from service.core.sim.robot import load_robot

    robot = load_robot()
    configure(robot.mjm, physics_dt()[1], ENGINE_SOLVER[engine])
    return robot.mjm, robot.home_key


def model_options(mjm: Any) -> dict[str, Any]:
    """The options that decide the cost of a step, for the JSON."""
    import mujoco

    o = mjm.opt
    return {
        "timestep": o.timestep,
        "solver": mujoco.mjtSolver(o.solver).name,
        "integrator": mujoco.mjtIntegrator(o.integrator).name,
        "cone": mujoco.mjtCone(o.cone).name,
        "iterations": o.iterations,
        "ls_iterations": o.ls_iterations,
        "nq": mjm.nq,
        "nv": mjm.nv,
        "ngeom": mjm.ngeom,
    }


# -- raw MuJoCo Warp ---------------------------------------------------------------------------


def raw_warp(nworld: int, device: str, dt: float) -> tuple[Any, Any]:
    """(mjw model, mjw data) of the scene at `home`, sized like the engine's."""
    import mujoco
    import mujoco_warp as mjw
    import warp as wp

    from service.engines.warp import NCONMAX, NJMAX

    mjm, home = engine_model(device, "warp")
    assert abs(mjm.opt.timestep - dt) < 1e-12, (mjm.opt.timestep, dt)
    mjd = mujoco.MjData(mjm)
    mujoco.mj_resetDataKeyframe(mjm, mjd, home)
    mujoco.mj_forward(mjm, mjd)
    with wp.ScopedDevice(device):
        m = mjw.put_model(mjm)
        d = mjw.put_data(mjm, mjd, nworld=nworld, nconmax=NCONMAX, njmax=NJMAX)
    return m, d


def home_key() -> int:
    """The id of the model's `home` keyframe."""
    return engine_model()[1]


def finite(d: Any) -> bool:
    """Every world's qpos of mjw data `d` is finite (the run did not blow up)."""
    import numpy as np

    return bool(np.isfinite(d.qpos.numpy()).all())


# -- native MuJoCo -----------------------------------------------------------------------------


class Rollout:
    """Raw native MuJoCo: `mujoco.rollout.Rollout` on `nthread` threads (0: the calling
    thread), chained calls from `home`, each continuing from the last one's state."""

    def __init__(
        self,
        nworld: int,
        nthread: int,
        physics_dt: float,
        solver: Any = None,
        target_call_s: float = 0.05,
    ) -> None:
        """`solver`: a mujoco.mjtSolver; None: the native engine's (physics.ENGINE_SOLVER).
        `target_call_s`: a call's length, so that the Python call overhead is noise."""
        import mujoco
        import numpy as np
        from mujoco import rollout

        from service.core.sim.physics import ENGINE_SOLVER, configure
        from service.core.sim.robot import load_robot

        robot = load_robot()
        self.mjm = mjm = robot.mjm
        configure(mjm, physics_dt, ENGINE_SOLVER["mujoco"] if solver is None else solver)
        data = mujoco.MjData(mjm)
        mujoco.mj_resetDataKeyframe(mjm, data, robot.home_key)
        mujoco.mj_forward(mjm, data)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state0 = np.empty(mujoco.mj_stateSize(mjm, spec))
        mujoco.mj_getState(mjm, data, state0, spec)
        # Steps per call: ~target_call_s a call at the reference figure of ~1e5 steps/s per
        # thread, at most 200 to bound the output.
        threads = max(1, nthread)
        self.nstep = int(min(200, max(1, math.ceil(target_call_s * 1e5 * threads / nworld))))
        self.nworld = nworld
        self.initial = np.tile(state0, (nworld, 1))
        self.control = np.tile(data.ctrl.copy(), (nworld, self.nstep, 1))
        self.states = np.empty((nworld, self.nstep, state0.size))
        self.datas = [mujoco.MjData(mjm) for _ in range(threads)]
        self.pool = rollout.Rollout(nthread=nthread)

    def call(self) -> None:
        """`nstep` steps of every world, continuing from where the last call left them."""
        self.pool.rollout(
            self.mjm, self.datas, self.initial, self.control, nstep=self.nstep, state=self.states
        )
        self.initial[:] = self.states[:, -1, :]

    def block(self, seconds: float, warm: bool = True) -> float:
        """World-steps/s over one block of about `seconds` (`warm`: after one untimed call)."""
        timing = common.time_calls(self.call, seconds, warmup_reps=int(warm))
        return timing.reps * self.nstep * self.nworld / timing.elapsed

    def finite(self) -> bool:
        """Every world's state is finite (the run did not blow up)."""
        import numpy as np

        return bool(np.isfinite(self.initial).all())

    def close(self) -> None:
        self.pool.close()
