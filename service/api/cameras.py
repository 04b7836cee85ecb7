"""Cameras over HTTP: the list with intrinsics, one world's image, many worlds' in one reply.

Nothing is drawn until one of these is asked; a reply's `X-Armfleet-Tick` says which tick the
image shows. Formats and the many-image layout: service/core/cameras/wire.py.
"""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, Depends, Header, Path, Query
from fastapi.responses import Response
from pydantic import BaseModel, Field

from service.api.deps import World, get_runtime
from service.core.cameras import wire as camera_wire
from service.core.cameras.feed import CameraFeed
from service.core.contract.replies import errors
from service.core.errors import Unavailable
from service.core.sim.worlds import WORLDS_PATTERN, parse_worlds
from service.runtime import Runtime

router = APIRouter(prefix="/v1", tags=["cameras"])


async def get_cameras(runtime: Annotated[Runtime, Depends(get_runtime)]) -> CameraFeed:
    if runtime.cameras is None:
        raise Unavailable(
            runtime.error or "simulation is starting (compiling kernels); see /readyz"
        )
    return runtime.cameras


Feed = Annotated[CameraFeed, Depends(get_cameras)]
Name = Annotated[str, Path(description="camera name, as GET /v1/cameras lists it")]
ImageQ = Annotated[str, Query(description="rgb, depth or seg", pattern="^(rgb|depth|seg)$")]
FormatQ = Annotated[
    str | None,
    Query(
        description="png, jpeg or raw (depth and seg asked as jpeg come as png: JPEG cannot "
        "hold them exactly); unset: from Accept, else png",
        pattern="^(png|jpeg|raw)$",
    ),
]
QualityQ = Annotated[int, Query(ge=1, le=100, description="JPEG quality")]


class CameraInfo(BaseModel):
    """One served camera: the model's camera at the size and outputs chosen at start."""

    name: str
    width: int
    height: int
    fovy: float = Field(description="vertical field of view [deg]")
    K: list[float] = Field(
        description="3x3 intrinsics, row-major, OpenCV/ROS convention (pixel centres at "
        "integer coordinates): fx = fy = (height/2)/tan(fovy/2), cx = (width-1)/2, "
        "cy = (height-1)/2"
    )
    outputs: list[str] = Field(description="what it draws: rgb, depth, seg")


class CameraList(BaseModel):
    cameras: list[CameraInfo]
    ready: bool = Field(
        description="the renderer is built and its kernels loaded (on the CPU, this list or "
        "the first picture asked starts the build)"
    )
    warm_s: float | None = Field(description="seconds the first draw of every camera took")


_IMAGE = {
    200: {
        "description": "the image; X-Armfleet-Tick: the tick it shows",
        "content": {t: {} for t in ("image/png", "image/jpeg", "application/octet-stream")},
    },
    **errors(404, 409),
}


@router.get("/cameras", response_model=CameraList, summary="The cameras, their size and K")
async def list_cameras(feed: Feed) -> CameraList:
    if feed.available:
        feed.open()  # a CPU service builds its renderer when cameras are first asked about
    ready = feed.available and feed.warm_s is not None
    return CameraList(
        cameras=[
            CameraInfo(
                name=c.name,
                width=c.width,
                height=c.height,
                fovy=c.fovy,
                K=c.K,
                outputs=list(c.outputs),
            )
            for c in feed.specs.values()
        ],
        ready=ready,
        warm_s=feed.warm_s,
    )


@router.get(
    "/worlds/{world}/cameras/{name}",
    response_class=Response,
    responses=_IMAGE,
    summary="What camera `name` sees in one world now (PNG, JPEG or raw; depth, segmentation)",
)
async def one_image(
    world: World,
    name: Name,
    feed: Feed,
    image: ImageQ = "rgb",
    format: FormatQ = None,
    quality: QualityQ = 90,
    accept: Annotated[str | None, Header(include_in_schema=False)] = None,
) -> Response:
    fmt = camera_wire.choose(image, format, accept)
    spec = feed.want(name, image)
    shot = await feed.shoot_async([world], name)
    pixels = shot.image(image)[0]
    body = await asyncio.to_thread(camera_wire.encode, pixels, image, fmt, quality)
    headers = {
        "X-Armfleet-Tick": str(shot.tick),
        "X-Armfleet-Size": f"{spec.width}x{spec.height}",
        "Cache-Control": "no-store",
    }
    return Response(body, media_type=camera_wire.CONTENT_TYPES[fmt], headers=headers)


@router.get(
    "/cameras/{name}/images",
    response_class=Response,
    responses={
        200: {
            "description": "every asked world's image in one binary message (layout in the "
            "camera guide: b'AFIM', u32 header length, JSON header, images)",
            "content": {camera_wire.MULTI_TYPE: {}},
        },
        **errors(404, 409),
    },
    summary="What camera `name` sees in many worlds at one tick, in one binary reply",
)
async def many_images(
    name: Name,
    feed: Feed,
    worlds: Annotated[str, Query(pattern=WORLDS_PATTERN, description="e.g. 0-15,20")] = "0",
    image: ImageQ = "rgb",
    format: FormatQ = None,
    quality: QualityQ = 90,
) -> Response:
    fmt = camera_wire.choose(image, format, None)
    feed.want(name, image)
    ids = parse_worlds(worlds, feed.loop.batch.nworld)
    shot = await feed.shoot_async(ids, name)
    body = await asyncio.to_thread(camera_wire.pack, shot, image, fmt, quality)
    return Response(body, media_type=camera_wire.MULTI_TYPE, headers={"Cache-Control": "no-store"})
