"""The ticks' first claim on the cores: a thread that serves requests gives way to the ticks.

Why: the serving process's event loop (sockets, commands, their acks and state frames) runs on
the same cores as the engine (the sim thread, the shard workers). Under a load of commands the
operating system shares the cores fairly between them, so each tick's engine work is cut into
by command work and the tick ends late. Nothing but the scheduler can give the engine the first
claim on a core; lowering the priority of the request-handling thread (a higher nice value) does
that without privileges, where raising the engine's needs them (CAP_SYS_NICE, root): where the
process has them, engine_priority.py raises the engine too (against other processes, which a
lower request thread cannot help with).

Linux sets priority per thread (`setpriority` on the thread's id), and a thread starts with the
priority of the thread that started it: the event loop's thread lowers itself after the sim
thread and the shard workers have started, so they keep the process's priority and the threads
the event loop starts later (surfaces, thread pools) take its lower one. Elsewhere (macOS,
Windows) priority is per process, so nothing is changed there.

One kind of thread must not give way: a protocol server whose clients drop the connection
after a deadline without data (ur_rtde gives up 2.5 s after its last RTDE package). A thread
cannot take back a nice step without privileges, so before the event loop's thread lowers
itself it leaves a nursery thread at the process's priority, and `start_at_process_priority`
starts such a thread from there (it inherits the nursery's priority, not the caller's).
"""

from __future__ import annotations

import concurrent.futures
import os
import queue
import sys
import threading


class _Nursery:
    """A thread at the process's priority that starts the threads it is handed (Linux: a new
    thread takes the priority of the thread that starts it)."""

    def __init__(self) -> None:
        self._jobs: queue.SimpleQueue[tuple[threading.Thread, concurrent.futures.Future[None]]]
        self._jobs = queue.SimpleQueue()
        threading.Thread(target=self._run, name="armfleet-nursery", daemon=True).start()

    def _run(self) -> None:
        while True:
            thread, done = self._jobs.get()
            try:
                thread.start()
            except BaseException as exc:  # handed back to the caller
                done.set_exception(exc)
            else:
                done.set_result(None)

    def start(self, thread: threading.Thread) -> None:
        done: concurrent.futures.Future[None] = concurrent.futures.Future()
        self._jobs.put((thread, done))
        done.result()


_nursery: _Nursery | None = None
_nursery_lock = threading.Lock()


def start_at_process_priority(thread: threading.Thread) -> None:
    """Start `thread` at the priority the process started with, even from a thread that
    lowered its own (see the module docstring); a plain start where none was lowered."""
    nursery = _nursery
    if nursery is None:
        thread.start()
    else:
        nursery.start(thread)


def lower_this_thread(steps: int) -> int | None:
    """Lower the calling thread's priority by `steps` nice steps (capped at 19): the nice value
    it runs at now, or None where priority is not per thread (not Linux) or the OS refused."""
    if not sys.platform.startswith("linux") or steps <= 0:
        return None
    global _nursery
    with _nursery_lock:
        if _nursery is None:  # started at this thread's priority, before it is lowered
            _nursery = _Nursery()
    tid = threading.get_native_id()
    try:
        now = os.getpriority(os.PRIO_PROCESS, tid)
        os.setpriority(os.PRIO_PROCESS, tid, min(19, now + steps))
        return os.getpriority(os.PRIO_PROCESS, tid)
    except OSError:
        return None
