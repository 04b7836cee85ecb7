"""Persistence as one service: everything a running armfleet saves, in one place.

Snapshots (`snapshots`: the store under `<data-dir>/snapshots`, saved on request, restored at a
tick boundary, `latest` on a clean stop) and the MCAP recording (`--record FILE` starts one with
the service; `POST /v1/recordings` starts one later, once the last has stopped). There is one
recording at a time and this service holds it, so the service keeps one recorder however many
were started, and stops the running one before the loop stops. What is written, off the sim
thread, is recorder.py; the snapshot files are snapshots.py.
"""

from __future__ import annotations

import logging
import threading

from service.core.errors import ArmfleetError, Conflict, Unavailable
from service.core.surface import SurfaceContext
from service.persistence.recorder import Recorder
from service.persistence.settings import PersistenceSettings
from service.persistence.snapshots import SnapshotStore

log = logging.getLogger("armfleet.recorder")


class Persistence:
    """Snapshots and the recording of one service (it records only when asked to)."""

    def __init__(self, settings: PersistenceSettings) -> None:
        self.snapshots = SnapshotStore(settings.data_dir)
        self.recordings_dir = self.snapshots.dir.parent / "recordings"
        self._ctx: SurfaceContext | None = None
        self._lock = threading.Lock()  # one start at a time: two must not both see none running
        self.current: Recorder | None = None  # the running or last recording
        # `--record`'s file is opened now, so that one that cannot be written stops the start
        # before anything is built (CannotWrite, raised by create_app).
        s = settings
        self._asked = (
            None
            if s.record is None
            else Recorder(s.record, s.record_worlds, s.record_rate, s.record_queue)
        )

    def start(self, ctx: SurfaceContext) -> None:
        """The loop runs: start `--record`'s recording, and let later ones start."""
        self._ctx = ctx
        recorder, self._asked = self._asked, None
        if recorder is None:
            return
        try:
            self.begin(recorder)
        except ArmfleetError as exc:  # e.g. the disk filled meanwhile: its status says why
            self.current = recorder
            log.error("--record did not start: %s", exc)

    def begin(self, recorder: Recorder) -> None:
        """Start `recorder` (waits for a tick boundary); Conflict while another one runs."""
        with self._lock:
            if self._ctx is None:
                raise Unavailable("the service is starting; see /readyz")
            last = self.current
            if last is not None and last.status.active:
                raise Conflict(f"a recording is already running ({last.path}); stop it first")
            if last is not None:
                last.stop()  # finished or failed: let its writer thread go
            recorder.start(self._ctx)
            self.current = recorder

    def stop(self) -> None:
        """Finish the recording (before the loop stops)."""
        if self._asked is not None:  # never started (the engine failed): close its file
            self._asked.stop()
        if self.current is not None:
            self.current.stop()

    def unfinished(self) -> list[str]:
        """The recording, if it stopped early or could not be finished (after `stop`)."""
        last = self.current
        if last is None or not last.status.error:
            return []
        return [f"recording {last.path} is incomplete: {last.status.error}"]
