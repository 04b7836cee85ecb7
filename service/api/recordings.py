"""Recordings: start and stop an MCAP recording of commands and world states while serving."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter

from service.api.deps import Rt, StateLoop, writes_file
from service.core.contract.replies import answers, errors
from service.core.contract.snapshots import RecordingRequest, RecordingStatus
from service.core.errors import NotFound
from service.core.sim.worlds import pick_worlds
from service.persistence.recorder import Recorder

router = APIRouter(prefix="/v1/recordings", tags=["recordings"])


def _status(recorder: Recorder) -> RecordingStatus:
    return recorder.status


@router.post(
    "",
    summary="Start recording to <data-dir>/recordings/<name>.mcap",
    **writes_file(
        RecordingStatus,
        {
            **errors(404),  # a world that `worlds` names does not exist
            409: {"description": "a recording is already running"},
        },
    ),
)
async def start(runtime: Rt, loop: StateLoop, body: RecordingRequest) -> RecordingStatus:
    # StateLoop: a recording starts from the full state.
    # Unknown worlds are a 404 before the file is opened (opening truncates one of that name).
    worlds = pick_worlds(body.worlds, loop.batch.nworld)
    path = runtime.persistence.recordings_dir / f"{body.name}.mcap"
    # Opening and starting write the file's beginning before answering: a file that cannot be
    # written is a 507 naming the cause, never an "active" recording that is not.
    queue_items = runtime.settings.persistence.record_queue
    recorder = await asyncio.to_thread(Recorder, path, worlds, body.rate, queue_items)
    # Conflict while one runs; waits for a tick boundary (off the event loop).
    await asyncio.to_thread(runtime.persistence.begin, recorder)
    return _status(recorder)


@router.get(
    "/current",
    summary="The running (or last) recording",
    **answers(RecordingStatus, 404),  # none started yet
)
async def current(runtime: Rt) -> RecordingStatus:
    recorder = runtime.persistence.current
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
    recorder = runtime.persistence.current
    if recorder is None or not recorder.status.active:
        last = recorder.status if recorder is not None else None
        why = f"; the last one ({last.path}) stopped early: {last.error}" if last else ""
        raise NotFound(f"no recording is running{why if last and last.error else ''}")
    await asyncio.to_thread(recorder.stop)
    return _status(recorder)
