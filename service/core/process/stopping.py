"""Who stops on SIGINT/SIGTERM: the serving process alone, once, saving what it holds.

A terminal's Ctrl-C sends SIGINT to the whole foreground process group, and supervisors
(systemd's control group, `kill -TERM -PGID`) send SIGTERM to every process they started. The
serving process has to save snapshot `latest` from its workers and finish a running recording
after such a signal, so the processes it starts (shard workers, a private Ray instance) must not
die of it first: they start with SIGINT and SIGTERM blocked (`signals_blocked`: a blocked mask
is inherited through fork and exec, so no signal reaches them while they import and build) and
workers then ignore both (`leave_stopping_to_parent`). The serving process stops them itself
once it has what it needs; a worker whose parent is gone sees its pipe close and exits.

Ignoring in the workers rather than moving them to a process group or session of their own:
ignoring also holds against signals sent to a whole control group (systemd), which a process
group does not, and the workers still share the terminal's job control and hang-up with the
service that owns them.

In the serving process (`StopSignals`) the first SIGINT or SIGTERM starts the graceful stop;
a second one exits at once (status 128 + signal) without waiting for anything to be saved.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
from collections.abc import Callable, Iterator
from multiprocessing.context import BaseContext
from typing import Any

log = logging.getLogger("armfleet")

STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})


@contextlib.contextmanager
def signals_blocked() -> Iterator[None]:
    """Block SIGINT and SIGTERM in this thread while it starts child processes.

    Children inherit the blocked mask, so a Ctrl-C that arrives while a worker still imports
    (seconds, before it could ignore anything) stays pending instead of killing it. A signal
    meant for this process meanwhile is delivered to another of its threads, or to this one
    when the block ends: it is delayed, never lost.
    """
    old = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def leave_stopping_to_parent() -> None:
    """In a worker process: ignore SIGINT and SIGTERM (pending ones are dropped), then unblock.

    The parent stops the worker over its pipe after it has saved the worker's state.
    """
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)


def start_worker(ctx: BaseContext, target: Callable[..., None], args: tuple[Any, ...]) -> Any:
    """A started daemon process of `ctx` running `target(*args)` that leaves stopping to us."""
    proc = ctx.Process(target=_leave_stopping_then, args=(target, *args), daemon=True)  # type: ignore[attr-defined]
    with signals_blocked():
        proc.start()
    return proc


def _leave_stopping_then(target: Callable[..., None], *args: Any) -> None:
    leave_stopping_to_parent()
    target(*args)


class StopSignals:
    """The serving process's SIGINT/SIGTERM handlers: stop gracefully once, then at once.

    `on_first(sig)` is called (in the main thread, between bytecodes) for the first signal and
    should only ask for the stop; a second signal, while stopping takes its time (saving,
    finishing a recording), writes one line to stderr, runs `on_quit` (kill what would outlive
    this process) and ends the process with 128 + signal.
    """

    def __init__(
        self, on_first: Callable[[int], None], on_quit: Callable[[], None] | None = None
    ) -> None:
        self._on_first = on_first
        self._on_quit = on_quit  # what must not outlive us even then (a private Ray instance)
        self.received: int | None = None
        self._previous: dict[int, object] = {}

    def install(self) -> None:
        """Take SIGINT and SIGTERM (main thread only; elsewhere signals cannot be handled)."""
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in STOP_SIGNALS:
            previous = signal.signal(sig, self._handle)
            self._previous.setdefault(sig, previous)

    def restore(self) -> None:
        """Put back the handlers that were there before `install`."""
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)  # type: ignore[arg-type]
        self._previous.clear()

    def _handle(self, sig: int, frame: object) -> None:
        name = signal.Signals(sig).name
        if self.received is None:
            self.received = sig
            log.warning(
                "%s: stopping (saving snapshot 'latest' and any recording first; "
                "send it again to quit at once without saving)",
                name,
            )
            self._on_first(sig)
            return
        os.write(2, f"armfleet: second {name}: quitting at once, nothing more is saved\n".encode())
        if self._on_quit is not None:
            with contextlib.suppress(Exception):
                self._on_quit()
        os._exit(128 + sig)


def reclaim_stop_signals() -> None:
    """Put this process's Python handlers back in front of SIGINT and SIGTERM (main thread).

    A library may install C-level handlers over them: Ray's core worker, in the process that
    calls `ray.init`, installs a crash reporter that on SIGTERM prints a stack dump and arms a
    3 s alarm that aborts the process, which would kill a stop that is still saving.
    """
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.getsignal(sig))
