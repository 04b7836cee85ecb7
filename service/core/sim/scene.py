"""The drawable scene as MuJoCo compiled it: bodies and their visual geoms, for viewers.

The browser page builds its 3D scene from this (GET /v1/scene) instead of knowing the robot, so
a change under mjcf/ shows in the page with no JavaScript touched. Geometry is static: each geom
is described in its body's frame, and the moving part (every body's world pose) is streamed per
tick (`Snapshot.body_pos` / `body_quat`, the pose frames of service/core/streams/wire.py).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

# Geom groups a viewer shows by default, as MuJoCo's own viewer does (0-2). Our MJCF keeps the
# robot's collision shapes in group 3 so that they are not drawn over the visual ones.
VISIBLE_GROUPS = (0, 1, 2)

_TYPES = {
    mujoco.mjtGeom.mjGEOM_PLANE: "plane",
    mujoco.mjtGeom.mjGEOM_SPHERE: "sphere",
    mujoco.mjtGeom.mjGEOM_CAPSULE: "capsule",
    mujoco.mjtGeom.mjGEOM_ELLIPSOID: "ellipsoid",
    mujoco.mjtGeom.mjGEOM_CYLINDER: "cylinder",
    mujoco.mjtGeom.mjGEOM_BOX: "box",
    mujoco.mjtGeom.mjGEOM_MESH: "mesh",
}


def _floats(values: np.ndarray) -> list[float]:
    return [round(float(v), 7) for v in values]


def _name(mjm: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(mjm, obj, i) or ""


def _mesh(mjm: mujoco.MjModel, mesh_id: int) -> dict[str, Any]:
    """Vertices (in the geom's frame, as compiled) and triangle indices of one mesh."""
    v0, nv = mjm.mesh_vertadr[mesh_id], mjm.mesh_vertnum[mesh_id]
    f0, nf = mjm.mesh_faceadr[mesh_id], mjm.mesh_facenum[mesh_id]
    return {
        "vertices": _floats(mjm.mesh_vert[v0 : v0 + nv].ravel()),
        "faces": [int(i) for i in mjm.mesh_face[f0 : f0 + nf].ravel()],
    }


def describe(mjm: mujoco.MjModel) -> dict[str, Any]:
    """Every body and every visible geom of a compiled model (the GET /v1/scene body).

    Colours come from the geom's material when it has one (MuJoCo does the same when drawing).
    Geom types a viewer cannot draw from size alone (height fields, SDFs) are left out and
    counted in `skipped`.
    """
    bodies = [
        {
            "id": b,
            "name": _name(mjm, mujoco.mjtObj.mjOBJ_BODY, b),
            "parent": int(mjm.body_parentid[b]),
        }
        for b in range(mjm.nbody)
    ]
    geoms: list[dict[str, Any]] = []
    skipped = 0
    for g in range(mjm.ngeom):
        if int(mjm.geom_group[g]) not in VISIBLE_GROUPS or mjm.geom_rgba[g, 3] == 0:
            continue
        kind = _TYPES.get(mujoco.mjtGeom(int(mjm.geom_type[g])))
        if kind is None:
            skipped += 1
            continue
        mat = int(mjm.geom_matid[g])
        rgba = mjm.mat_rgba[mat] if mat >= 0 else mjm.geom_rgba[g]
        geom: dict[str, Any] = {
            "id": g,
            "name": _name(mjm, mujoco.mjtObj.mjOBJ_GEOM, g),
            "body": int(mjm.geom_bodyid[g]),
            "type": kind,
            "size": _floats(mjm.geom_size[g]),
            "pos": _floats(mjm.geom_pos[g]),
            "quat": _floats(mjm.geom_quat[g]),
            "rgba": _floats(rgba),
        }
        if kind == "mesh":
            geom["mesh"] = _mesh(mjm, int(mjm.geom_dataid[g]))
        geoms.append(geom)
    return {"nbody": int(mjm.nbody), "bodies": bodies, "geoms": geoms, "skipped": skipped}
