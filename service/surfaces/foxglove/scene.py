"""What Foxglove draws of a world: its geoms as scene entities in their bodies' frames, and where
each shown world sits in the shared `world` frame. Pure functions of the model, for the live
server (live.py)."""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    Pose,
    Quaternion,
    SceneEntity,
    SpherePrimitive,
    Timestamp,
    Vector3,
)

SPACING = 2.5  # m between neighbouring worlds in the shared `world` frame
_VISIBLE_GROUPS = (0, 1, 2)  # MuJoCo's viewer shows these groups by default
_FLOOR_HALF = 1.2  # m: the (infinite) floor plane drawn as a square tile per world


def world_offset(index: int, count: int) -> tuple[float, float]:
    """Where the `index`-th shown world stands in the shared frame (a square-ish grid)."""
    cols = max(1, math.ceil(math.sqrt(count)))
    return (index % cols) * SPACING, (index // cols) * SPACING


def quat_msg(wxyz: np.ndarray) -> Quaternion:
    return Quaternion(x=float(wxyz[1]), y=float(wxyz[2]), z=float(wxyz[3]), w=float(wxyz[0]))


def vec_msg(xyz: Any) -> Vector3:
    return Vector3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))


def pose_msg(pos: Any, wxyz: Any) -> Pose:
    return Pose(position=vec_msg(pos), orientation=quat_msg(np.asarray(wxyz)))


def geom_entities(mjm: mujoco.MjModel, prefix: str, stamp: Timestamp) -> list[SceneEntity]:
    """One SceneEntity per body with visible geoms, in the body's frame `<prefix>/<body>`."""
    per_body: dict[int, dict[str, list[Any]]] = {}
    for g in range(mjm.ngeom):
        if mjm.geom_group[g] not in _VISIBLE_GROUPS:
            continue
        rgba = mjm.mat_rgba[mjm.geom_matid[g]] if mjm.geom_matid[g] >= 0 else mjm.geom_rgba[g]
        if rgba[3] == 0:
            continue
        color = Color(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))
        size, pos, quat = mjm.geom_size[g], mjm.geom_pos[g], mjm.geom_quat[g]
        prims = per_body.setdefault(
            int(mjm.geom_bodyid[g]), {"cubes": [], "cylinders": [], "spheres": []}
        )
        kind = mujoco.mjtGeom(int(mjm.geom_type[g]))
        if kind == mujoco.mjtGeom.mjGEOM_BOX:
            prims["cubes"].append(
                CubePrimitive(pose=pose_msg(pos, quat), size=vec_msg(2 * size), color=color)
            )
        elif kind == mujoco.mjtGeom.mjGEOM_PLANE:
            tile = (2 * _FLOOR_HALF, 2 * _FLOOR_HALF, 0.002)
            prims["cubes"].append(
                CubePrimitive(pose=pose_msg(pos, quat), size=vec_msg(tile), color=color)
            )
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            prims["spheres"].append(
                SpherePrimitive(
                    pose=pose_msg(pos, quat), size=vec_msg([2 * size[0]] * 3), color=color
                )
            )
        elif kind in (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE):
            r, half = float(size[0]), float(size[1])
            prims["cylinders"].append(
                CylinderPrimitive(
                    pose=pose_msg(pos, quat),
                    size=vec_msg((2 * r, 2 * r, 2 * half)),
                    bottom_scale=1.0,
                    top_scale=1.0,
                    color=color,
                )
            )
            if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
                for sign in (-1.0, 1.0):
                    end = np.zeros(3)
                    mujoco.mju_rotVecQuat(end, np.array([0.0, 0.0, sign * half]), quat)
                    prims["spheres"].append(
                        SpherePrimitive(
                            pose=pose_msg(pos + end, quat), size=vec_msg([2 * r] * 3), color=color
                        )
                    )
    out = []
    for body, p in sorted(per_body.items()):
        name = mjm.body(body).name
        out.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=f"{prefix}/{name}",
                id=f"{prefix}/{name}",
                frame_locked=True,
                cubes=p["cubes"],
                cylinders=p["cylinders"],
                spheres=p["spheres"],
            )
        )
    return out
