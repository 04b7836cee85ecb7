"""Recordings: start and stop an MCAP recording of commands and world states while serving."""

from __future__ import annotations

import asyncio
import dataclasses
from typing import Annotated

from fastapi import APIRouter, Depends

from service.api.deps import Loop, get_runtime
from service.core.errors import NotFound
from service.core.schemas import RecordingRequest, RecordingStatus
from service.persistence.recorder import Recorder
from service.persistence.snapshots import check_state_support
from service.runtime import Runtime
from service.surfaces.recordings import Recordings

router = APIRouter(prefix="/v1/recordings", tags=["recordings"])
Rt = Annotated[Runtime, Depends(get_runtime)]


def _status(recorder: Recorder) -> RecordingStatus:
    return RecordingStatus(**dataclasses.asdict(recorder.status))


@router.post(
    "",
    response_model=RecordingStatus,
    status_code=201,
    summary="Start recording to <data-dir>/recordings/<name>.mcap",
    responses={409: {"description": "a recording is already running"}},
)
async def start(runtime: Rt, loop: Loop, body: RecordingRequest) -> RecordingStatus:
    check_state_support(loop.batch)  # a recording starts from the full state
    path = runtime.snapshots.dir.parent / "recordings" / f"{body.name}.mcap"
    recorder = Recorder(path, body.worlds, body.rate, runtime.settings.record_queue)
    # Conflict while one runs; waits for a tick boundary (off the event loop).
    await asyncio.to_thread(runtime.surfaces.of(Recordings).begin, recorder)
    return _status(recorder)


@router.get("/current", response_model=RecordingStatus, summary="The running (or last) recording")
async def current(runtime: Rt) -> RecordingStatus:
    recorder = runtime.surfaces.of(Recordings).current
    if recorder is None:
        raise NotFound("no recording has been started")
    return _status(recorder)


@router.delete(
    "/current",
    response_model=RecordingStatus,
    summary="Stop the running recording; replies once the file is complete",
    responses={404: {"description": "no recording is running"}},
)
async def stop(runtime: Rt) -> RecordingStatus:
    recorder = runtime.surfaces.of(Recordings).current
    if recorder is None or not recorder.status.active:
        raise NotFound("no recording is running")
    await asyncio.to_thread(recorder.stop)
    return _status(recorder)
