"""The drawable scene's schema (GET /v1/scene): bodies, meshes and geoms as the page and other
viewers draw them; built by service/core/sim/scene.py from the compiled model."""

from __future__ import annotations

from pydantic import BaseModel, Field


class SceneBody(BaseModel):
    id: int = Field(description="MjModel body index; row of the pose frames' body axis")
    name: str
    parent: int = Field(description="parent body id (the world body, 0, is its own parent)")


class SceneMesh(BaseModel):
    vertices: list[float] = Field(description="x y z per vertex, flattened [m], geom frame")
    faces: list[int] = Field(description="3 vertex indices per triangle, flattened")


class SceneGeom(BaseModel):
    """One visible geom, described in its body's frame as MuJoCo compiled it."""

    id: int = Field(description="MjModel geom index")
    name: str = Field(description="empty when the MJCF gave none")
    body: int = Field(description="body the geom is attached to")
    type: str = Field(description="plane, sphere, capsule, ellipsoid, cylinder, box or mesh")
    size: list[float] = Field(
        description="MuJoCo geom_size [m]: box half-extents; sphere radius; capsule/cylinder "
        "radius and half-length along the local z axis; plane half-sizes (0 = infinite)"
    )
    pos: list[float] = Field(description="x y z in the body frame [m]")
    quat: list[float] = Field(description="orientation in the body frame, w x y z")
    rgba: list[float] = Field(description="colour, 0..1 (the material's when it has one)")
    mesh: SceneMesh | None = Field(None, description="mesh geoms only")


class Scene(BaseModel):
    nbody: int = Field(description="bodies per world in the pose frames (world body included)")
    bodies: list[SceneBody]
    geoms: list[SceneGeom] = Field(description="geoms of groups 0-2 (MuJoCo's visible groups)")
    skipped: int = Field(description="visible geoms of types not described (height fields, SDFs)")
