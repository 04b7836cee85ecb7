"""The ticks' first claim on the cores: a thread that serves requests gives way to the ticks.

Why: the serving process's event loop (sockets, commands, their acks and state frames) runs on
the same cores as the engine (the sim thread, the shard workers). Under a load of commands the
operating system shares the cores fairly between them, so each tick's engine work is cut into
by command work and the tick ends late. Nothing but the scheduler can give the engine the first
claim on a core; lowering the priority of the request-handling thread (a higher nice value) does
that without privileges, where raising the engine's would need them (CAP_SYS_NICE, root).

Linux sets priority per thread (`setpriority` on the thread's id), and a thread starts with the
priority of the thread that started it: the event loop's thread lowers itself after the sim
thread and the shard workers have started, so they keep the process's priority and the threads
the event loop starts later (surfaces, thread pools) take its lower one. Elsewhere (macOS,
Windows) priority is per process, so nothing is changed there.
"""

from __future__ import annotations

import os
import sys
import threading


def lower_this_thread(steps: int) -> int | None:
    """Lower the calling thread's priority by `steps` nice steps (capped at 19): the nice value
    it runs at now, or None where priority is not per thread (not Linux) or the OS refused."""
    if not sys.platform.startswith("linux") or steps <= 0:
        return None
    tid = threading.get_native_id()
    try:
        now = os.getpriority(os.PRIO_PROCESS, tid)
        os.setpriority(os.PRIO_PROCESS, tid, min(19, now + steps))
        return os.getpriority(os.PRIO_PROCESS, tid)
    except OSError:
        return None
