"""Recorder: writes commands, restores and world states to an MCAP file without slowing the loop.

The recorder hears three things: every accepted command (a `control` listener, on the caller's
thread), every restore (a loop listener, on the sim thread) and snapshots at whole ticks of the
chosen rate (a loop sink, on the sim thread). Each of these only puts an item on a bounded queue;
a writer thread of its own serialises and writes (layout: `mcap_log.py`). If the disk cannot
keep up and the queue fills, the recording stops with an error naming why and where, the file is
closed with what was written, and the simulation goes on untouched.

A recording starts from the full batch state at a tick boundary (taken through the loop and
embedded in the file), so `armfleet replay` can rebuild exactly what followed.

Failures reach whoever started the recording: the file is opened when the recorder is made
(`serve --record` to a path that cannot be written stops before anything is built) and `start`
writes and flushes the file's header and starting state before it returns, so a disk that is
full or read-only, a FIFO without a reader or a writer that cannot work (its compression library
missing) raise `CannotWrite` naming the cause instead of answering "active". Later failures stop
the recording with the reason in its status (`service.persistence.storage` keeps a stuck reader from
hanging the writer).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from service.core.commands.registry import BY_KIND
from service.core.commands.trajectory.commands import ResumeTrajectory
from service.core.contract.snapshots import RecordingStatus
from service.core.sim.loop_types import SnapshotSink
from service.core.sim.types import BatchState, Snapshot
from service.core.sim.worlds import pick_worlds
from service.persistence.mcap_log import COMMANDS, RESTORES, STATUS, McapLog
from service.persistence.provenance import batch_header
from service.persistence.snapshots import encode_state
from service.persistence.storage import GuardedWriter, cannot_write, describe, open_for_writing

if TYPE_CHECKING:
    from service.core.commands.base import Accepted
    from service.core.commands.trajectory.status import Resumable
    from service.core.surface import SurfaceContext

log = logging.getLogger("armfleet.recorder")

QUEUE_ITEMS = 2048  # items (a command, a restore, or one snapshot of the recorded worlds)
_STOP = object()


def every_ticks(rate: float, control_hz: float) -> int:
    """A state every this many ticks for `rate` states per simulated second (at least 1; at
    most one per 2**31 ticks, so that a tiny rate is a long period, never an overflow)."""
    return max(1, min(2**31, round(min(control_hz / rate, 2.0**31))))


class Recorder(SnapshotSink):
    """One recording from `start` to `stop` (or until it fails); persistence/service.py holds
    the running one as a surface."""

    name = "recorder"

    def __init__(
        self,
        path: Path | str,
        worlds: Sequence[int] | str | None = None,
        rate: float = 30.0,
        queue_items: int = QUEUE_ITEMS,
        block: bool = False,
    ):
        """`worlds`: ids, a spec like "0-7,12", or None for the first 8; `block` (replay only)
        waits for the disk instead of failing, since nothing live is slowed by it there."""
        self.path = Path(path).expanduser()
        try:
            self._file: GuardedWriter | None = open_for_writing(self.path)
        except OSError as exc:
            raise cannot_write("recording", self.path, exc) from None
        self._worlds_arg = worlds
        self._worlds: np.ndarray | None = None
        self._rate = float(rate)
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=queue_items)
        self._block = block
        self._error: str | None = None
        self._active = False
        self._written = 0
        self._every = 1
        self._start_tick = 0
        self._last_tick: int | None = None
        self._thread: threading.Thread | None = None
        self._ctx: SurfaceContext | None = None
        self._header: dict[str, Any] = {}
        self._names: list[str] = []

    # -- life cycle ------------------------------------------------------------------------

    def start(self, ctx: SurfaceContext) -> None:
        """Hook into control and the loop, take the starting state, start the writer thread."""
        loop, control = ctx.loop, ctx.control
        self._ctx = ctx
        batch = loop.batch
        worlds = self._worlds_arg
        if worlds is None or isinstance(worlds, str):
            worlds = pick_worlds(worlds, batch.nworld)
        self._worlds = np.array(sorted(set(worlds)), dtype=np.int64)
        self._every = every_ticks(self._rate, batch.control_hz)
        self._header = batch_header(batch)
        self._names = list(batch.spec.names)
        self._active = True
        # Listen first: a command accepted while the state is being taken is then either in the
        # state (applied before it) or in the queue (tick after it); the writer sorts them out.
        control.add_listener(self._on_command)
        loop.listeners.add_restore_listener(self._on_restore)
        try:
            # The state and the trajectories running in it, at one tick boundary.
            taken = loop.call(
                lambda b: (loop.state_door.state_of(b), control.trajectories.running())
            )
            state, running = taken.result(timeout=60)
        except BaseException:
            self._give_up()
            raise
        try:
            out = self._begin(state, running)
        except Exception as exc:
            error = cannot_write("recording", self.path, exc)
            self._fail(error.detail)
            self._give_up()
            raise error from None
        self._start_tick = state.tick
        # The starting state is that tick's, in the file already: a later snapshot of the same
        # tick (a paused loop publishes writes it applied at once, StateDoor._settle) is not.
        self._last_tick = state.tick
        self._thread = threading.Thread(
            target=self._run, args=(out,), name="armfleet-recorder", daemon=True
        )
        self._thread.start()
        loop.listeners.add_sink(self)
        log.info(
            "recording worlds %s every %d ticks to %s from tick %d",
            _ranges(self._worlds),
            self._every,
            self.path,
            state.tick,
        )

    def stop(self) -> None:
        """Stop listening, write what is queued, close the file (waits for the writer)."""
        if self._ctx is None or self._thread is None:  # never started: nothing to finish
            self._close()
            return
        was_active = self._active
        self._detach()
        self._active = False
        while was_active and self._thread.is_alive():
            try:  # the writer drains the queue, or gives up (a stuck write fails in STALL_S)
                self._queue.put(_STOP, timeout=0.5)
                break
            except queue.Full:
                continue
        wait = 30.0 if was_active else 5.0
        self._thread.join(timeout=wait)
        if self._thread.is_alive():
            self._fail(f"the writer did not finish {self.path} in {wait:.0f} s")

    def _give_up(self) -> None:
        self._detach()
        self._active = False
        self._close()

    def _close(self) -> None:
        if self._file is not None:
            file, self._file = self._file, None
            try:
                file.close()
            except OSError as exc:
                self._fail(f"closing {self.path} failed: {describe(exc)}")

    def _detach(self) -> None:
        ctx = self._ctx
        if ctx is None:
            return
        ctx.control.remove_listener(self._on_command)
        ctx.loop.listeners.remove_restore_listener(self._on_restore)
        ctx.loop.listeners.remove_sink(self)

    @property
    def status(self) -> RecordingStatus:
        return RecordingStatus(
            path=str(self.path),
            worlds=[] if self._worlds is None else [int(w) for w in self._worlds],
            every_ticks=self._every,
            start_tick=self._start_tick,
            active=self._active and self._error is None,  # one answer, whatever thread reads
            written=self._written,
            error=self._error,
        )

    # -- producers (any thread; cheap, never block) ----------------------------------------

    def _offer(self, item: tuple[Any, ...]) -> None:
        if not self._active:
            return
        if self._block:
            self._queue.put(item)
            return
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self._fail(
                f"the disk could not keep up: {self._queue.maxsize} items waiting to be written "
                f"to {self.path}; recording stopped (the simulation goes on)"
            )

    def _fail(self, why: str) -> None:
        # Inactive before the error shows: a status read from another thread never says
        # "active" beside an error (the suite caught one in between, under load).
        self._active = False
        if self._error is None:
            self._error = why
            log.error("recording stopped: %s", why)
        self._detach()

    def _on_command(self, accepted: Accepted) -> None:
        self._offer(("command", time.time_ns(), accepted))

    def _on_restore(self, tick_before: int, state: BatchState, name: str) -> None:
        self._last_tick = None
        self._offer(("restore", time.time_ns(), tick_before, state, name))

    # The loop sink: a snapshot at every `every`-th tick, handed over as it is (immutable).
    def wants_snapshot(self, now: float) -> bool:
        ctx = self._ctx
        return self._active and ctx is not None and ctx.loop.tick % self._every == 0

    def publish(self, snapshot: Snapshot) -> None:
        if snapshot.tick % self._every or snapshot.tick == self._last_tick:
            return
        self._last_tick = snapshot.tick
        self._offer(("state", time.time_ns(), snapshot))

    # -- the writer thread -----------------------------------------------------------------

    def _run(self, out: McapLog) -> None:
        assert self._file is not None
        try:
            while True:
                item = self._queue.get()
                if item is _STOP or self._error is not None:
                    break
                self._write(out, item)
                self._written += 1
            out.json(STATUS, time.time_ns(), {"event": "stop", "detail": self._error})
            out.finish()
            self._file.sync()
        except Exception as exc:
            self._fail(f"writing {self.path} failed: {describe(exc)}")
        finally:
            self._close()

    def _begin(self, state: BatchState, running: list[Resumable]) -> McapLog:
        """The file's header, metadata, starting state and the trajectories running in it
        (replay puts them back before its first tick), written through to the file now."""
        assert self._worlds is not None and self._file is not None
        out = McapLog(self._file, self._header, self._names)
        attachment = out.attach_state(state.tick, encode_state(state, self._header, "start"))
        out.metadata(
            {
                **self._header,
                "worlds": [int(w) for w in self._worlds],
                "every_ticks": self._every,
                "rate": self._rate,
                "start_tick": state.tick,
                "start_state": attachment,
                "joint_names": self._names,
            }
        )
        out.json(STATUS, time.time_ns(), {"event": "start", "tick": state.tick})
        for run in running:
            resume = {"source": "recording", "kind": ResumeTrajectory.kind, "worlds": [run.world]}
            resume |= {"targets": [run.target], "tick": state.tick + 1}
            out.json(COMMANDS, time.time_ns(), {**resume, "trajectory": run.as_json()})
        self._file.flush()
        return out

    def _write(self, out: McapLog, item: tuple[Any, ...]) -> None:
        kind, wall_ns = item[0], item[1]
        if kind == "state":
            snap: Snapshot = item[2]
            assert self._worlds is not None
            out.joint_states(wall_ns, snap.tick, self._worlds, snap)
        elif kind == "command":
            a: Accepted = item[2]
            if BY_KIND[a.kind].replayed and a.tick <= self._start_tick:
                return  # applied before the starting state was taken: already in it
            out.json(
                COMMANDS,
                wall_ns,
                {
                    "source": str(a.source),
                    "kind": a.kind,
                    "worlds": a.worlds,
                    "targets": a.targets,
                    "tick": a.tick,
                    **a.record,
                },
            )
        elif kind == "restore":
            tick_before, state, name = item[2], item[3], item[4]
            attachment = out.attach_state(state.tick, encode_state(state, self._header, name))
            out.json(
                RESTORES,
                wall_ns,
                {
                    "tick_before": tick_before,
                    "tick": state.tick,
                    "name": name,
                    "attachment": attachment,
                },
            )


def _ranges(worlds: np.ndarray) -> str:
    """[0 1 2 3 7] → '0-3,7' for log lines."""
    out, start, prev = [], None, None
    for w in [int(x) for x in worlds]:
        if start is None:
            start = prev = w
        elif w == prev + 1:  # type: ignore[operator]
            prev = w
        else:
            out.append(f"{start}-{prev}" if start != prev else f"{start}")
            start = prev = w
    if start is not None:
        out.append(f"{start}-{prev}" if start != prev else f"{start}")
    return ",".join(out)
