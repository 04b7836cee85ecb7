"""What a saved file (snapshot, recording) must say about the batch that made it.

A state only continues bit-identically in a batch of the same compiled model (options such as
timestep and solver included), the same number of worlds and the same tick layout. Snapshots and
recordings carry this header and refuse to be restored or replayed into anything else.
"""

from __future__ import annotations

import copy
import hashlib
import importlib.metadata
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

if TYPE_CHECKING:
    from service.core.sim.batch import Batch

_PACKAGES = ("mujoco", "mujoco-warp", "warp-lang", "numpy", "armfleet")


def model_hash(mjm: mujoco.MjModel) -> str:
    """sha256 of the compiled model as MuJoCo saves it (MJB): geometry, masses and options.

    The constraint solver is left out (hashed as CG): each engine steps with its own
    (physics.ENGINE_SOLVER), and a state moves between engines, as it does between devices;
    within one engine the solver is the same, so the hash still says "the same model".
    """
    if mjm.opt.solver != mujoco.mjtSolver.mjSOL_CG:
        mjm = copy.copy(mjm)
        mjm.opt.solver = mujoco.mjtSolver.mjSOL_CG
    buf = np.zeros(mujoco.mj_sizeModel(mjm), dtype=np.uint8)
    mujoco.mj_saveModel(mjm, None, buf)
    return hashlib.sha256(buf.tobytes()).hexdigest()


def versions() -> dict[str, str]:
    """Versions of the packages whose change may change the numbers."""
    out = {}
    for name in _PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "unknown"
    return out


def batch_header(batch: Batch) -> dict[str, Any]:
    """The facts that decide whether a state fits a batch, plus where it was made (JSON-able).

    model_hash: see `model_hash`; nworld; control_hz [Hz]; physics_dt [s]; substeps per tick;
    device (e.g. "cpu"); engine (the batch class); versions (package → version).
    """
    return {
        "model_hash": model_hash(batch.robot.mjm),  # type: ignore[attr-defined]
        "nworld": int(batch.nworld),
        "control_hz": float(batch.control_hz),
        "physics_dt": float(batch.physics_dt),
        "substeps": int(batch.substeps),
        "device": str(batch.device_name),
        "engine": type(batch).__name__,
        "versions": versions(),
    }


def mismatch(saved: dict[str, Any], current: dict[str, Any]) -> str | None:
    """Why a state saved under header `saved` cannot continue in a batch with `current`, or None.

    Device, engine and versions are not checked: a state moves between them (it then continues
    correctly, though not necessarily bit-identically).
    """
    if saved.get("nworld") != current["nworld"]:
        return f"it holds {saved.get('nworld')} worlds, this service runs {current['nworld']}"
    steps = (saved.get("substeps"), saved.get("physics_dt"))
    if steps != (current["substeps"], current["physics_dt"]):
        return (
            f"it was stepped with {steps[0]} substeps of {steps[1]} s per tick, this service "
            f"steps {current['substeps']} of {current['physics_dt']} s"
        )
    if saved.get("model_hash") != current["model_hash"]:
        return (
            f"it was saved from another model (model hash {str(saved.get('model_hash'))[:12]}…, "
            f"this service runs {current['model_hash'][:12]}…; the MJCF or MuJoCo changed)"
        )
    return None
