"""The engine's first claim on the cores: in real time, the threads that step the worlds run at
a raised priority, when the process may raise one (`--engine-priority auto`, the default).

Why: lowering our own request threads (priority.py) helps only against our own work. When the
competitors are other processes (32 ur_rtde programs polling their receive threads beside a
`--ur` service on 2 cores, bench section 32) the scheduler shares the cores fairly among every
runnable thread of the box, and the sim thread lost enough turns that the ticks ran at 0.72 of
real time. ros2_control's controller_manager and the audio servers answer the same problem the
same way: ask the kernel for more for the thread that keeps time, when the process is permitted
(root, CAP_SYS_NICE, or an RLIMIT_NICE that allows it), say so in the log, and run as before
(one line saying why) when it is not.

Why a nice value and not SCHED_FIFO/RR: a real-time class runs a thread before every normal
one for as long as it wants the core. A fast-mode engine never sleeps and a real-time one that
falls behind does not either; under FIFO they would hold their cores from the event loop that
must answer the `pause` or the stop, from the user's shell and from the client programs the
ticks exist for (only the kernel's 95% RT throttle would leave anything). A nice value
only weighs the shares: RAISE_STEPS steps above the process's own nice give an engine thread
about 9x the share of a thread at the process's nice (CFS weights 9548 vs 1024) while every
other thread keeps running. It is set relative to the process's own nice, so a service started
under `nice -n 10` raises its engine to 0, above its own clients, not above the rest of the box.

Only in real time: in fast mode the engine takes every core it can by design, and a raised one
would leave the request threads a tenth of them; in paused mode it sleeps. The sim thread calls
`follow` at every turn of its loop; it raises (and lowers back, which needs no privilege) its
own thread and the engine's other stepping threads or worker processes (`stepping`: native
MuJoCo's pool threads, MuJoCo Warp's shard workers, rebuilt ones included) when the mode or
that set changes. Linux only: elsewhere priority is per process and nothing is changed.

A raised engine must not leave a thread with a deadline of its own behind the clients it
serves: the UR ports' thread (ur_rtde drops a connection 2.5 s after its last RTDE package)
is a companion (`add_companion`), raised COMPANION_STEPS with the engine and put back with it.
Measured: with the sim thread raised and the UR thread left at the process's nice, on a 2-core
box at load 30-50, the ticks of bench section 32 went from 0.59 to 0.84 of real time but the
UR thread went 2.6 s without sending and 12 of the 32 ur_rtde programs lost their connection
(32 of 32 without the raise).
"""

from __future__ import annotations

import logging
import os
import resource
import sys
import threading
from collections.abc import Callable, Sequence
from typing import Any, Literal, TypeVar

log = logging.getLogger("armfleet.priority")

RAISE_STEPS = 10  # nice steps above the process's own nice, in real time
# A companion (a thread with a deadline of its own that serves the engine's clients: the UR
# ports' thread) is raised this many steps with the engine, so the order stays engine first,
# then the companion, then the process's other threads and the clients.
COMPANION_STEPS = 5
NICEST = -20  # the kernel's highest priority nice value

Setting = Literal["auto", "off"]
T = TypeVar("T")


def _lowest_permitted() -> int:
    """The lowest nice RLIMIT_NICE lets this process set without CAP_SYS_NICE (20 - limit)."""
    soft, _ = resource.getrlimit(resource.RLIMIT_NICE)
    return NICEST if soft == resource.RLIM_INFINITY else 20 - int(soft)


def threads_started_by(build: Callable[[], T]) -> tuple[T, tuple[int, ...]]:
    """What `build()` returns, and the ids of the threads of this process that appeared while
    it ran (Linux; none elsewhere): how the pool threads a C library starts are found (native
    MuJoCo's). A thread another of ours starts in the same moment would be counted too; the
    window is one constructor's."""
    before = _task_ids()
    out = build()
    return out, tuple(sorted(_task_ids() - before))


def _task_ids() -> set[int]:
    try:
        return {int(name) for name in os.listdir("/proc/self/task")}
    except OSError:
        return set()


def nice_of(tid: int) -> int | None:
    """The nice value of thread (or process) `tid`; None when it is gone."""
    try:
        return os.getpriority(os.PRIO_PROCESS, tid)
    except OSError:
        return None


class EnginePriority:
    """The engine's threads' priority, raised while time runs in real time (module docstring)."""

    def __init__(self, setting: Setting, stepping: Callable[[], Sequence[int]]) -> None:
        self.setting = setting
        self._stepping = stepping  # ids of the engine's other stepping threads and processes
        self._linux = sys.platform.startswith("linux")
        self.permitted: bool | None = None  # None: not tried yet (or off, or not Linux)
        self.base: int | None = None  # the sim thread's nice when it first called `follow`
        self.raised_to: int | None = None  # the nice the engine runs at while raised
        self._tid: int | None = None
        self._raised: bool | None = None  # what was last applied (None: nothing yet)
        self._applied: tuple[int, ...] = ()
        self._companions: dict[int, int] = {}  # thread id -> steps (`add_companion`)
        self._met = 0  # how many companions were applied
        self._lock = threading.Lock()  # `status` reads from other threads

    def follow(self, realtime: bool) -> None:
        """The sim thread, every turn of its loop: raise the engine's threads in real time,
        put them back otherwise; only a change of mode or of the engine's threads costs a call."""
        if self._tid is None:
            self._meet()
        if not self.permitted:
            return
        ids = tuple(self._stepping())
        if realtime is self._raised and ids == self._applied and self._met == len(self._companions):
            return
        with self._lock:
            assert self._tid is not None and self.base is not None and self.raised_to is not None
            self._set((self._tid, *ids), self.raised_to if realtime else self.base)
            for tid, steps in list(self._companions.items()):
                raised = max(self.raised_to, self.base - steps)
                self._set((tid,), raised if realtime else self.base)
            self._raised, self._applied, self._met = realtime, ids, len(self._companions)

    def add_companion(self, tid: int, steps: int = COMPANION_STEPS) -> None:
        """Raise thread `tid` `steps` nice steps (no more than the engine) whenever the engine
        is raised, and put it back with it: a thread that serves the engine's clients under a
        deadline of its own (ur_rtde drops a connection 2.5 s after its last RTDE package),
        which a raised engine must not leave behind the clients' own threads. Any thread."""
        with self._lock:
            self._companions[tid] = steps

    def _meet(self) -> None:
        """The first call, on the sim thread: note the threads and their nice, then (auto, on
        Linux) try the raise."""
        with self._lock:
            self._tid = threading.get_native_id()
            self.base = nice_of(self._tid)
            self._applied = tuple(self._stepping())
            if self.setting == "auto" and self._linux and self.base is not None:
                self._first_raise()

    def _first_raise(self) -> None:
        """Try the raise on the sim thread: settle `raised_to` (RLIMIT_NICE may allow less
        than RAISE_STEPS) and `permitted`, and say in the log which it was."""
        assert self._tid is not None and self.base is not None
        base = self.base
        want = max(NICEST, base - RAISE_STEPS)
        for nice in dict.fromkeys((want, max(want, _lowest_permitted()))):
            if nice >= base:
                continue
            try:
                os.setpriority(os.PRIO_PROCESS, self._tid, nice)
            except OSError:
                continue
            self.permitted, self.raised_to = True, nice
            log.info(
                "engine priority: the threads that step the worlds run at nice %d in real "
                "time, %d above the process's %d (--engine-priority off: not)",
                nice,
                base - nice,
                base,
            )
            return
        self.permitted = False
        log.info(
            "engine priority: not permitted to raise the engine's threads above nice %d (needs "
            "root, CAP_SYS_NICE or an RLIMIT_NICE of %d or more); they share the cores with "
            "every other thread at that nice",
            base,
            20 - want,
        )

    @staticmethod
    def _set(ids: Sequence[int], nice: int) -> None:
        for tid in ids:
            try:
                os.setpriority(os.PRIO_PROCESS, tid, nice)
            except ProcessLookupError:  # a worker that just died: its rebuild comes next
                continue
            except PermissionError:
                log.warning("engine priority: could not set thread %d to nice %d", tid, nice)

    def status(self) -> dict[str, Any]:
        """What the engine's threads run at now (GET /v1/ur): the setting, whether raising was
        permitted, the process's nice and the raised one, each thread's id and nice (the sim
        thread first), and the companions'."""
        with self._lock:
            ids = () if self._tid is None else (self._tid, *self._applied)
            return {
                "companions": [{"id": t, "nice": nice_of(t)} for t in self._companions],
                "setting": self.setting,
                "permitted": self.permitted,
                "raised": bool(self._raised) and bool(self.permitted),
                "process_nice": self.base,
                "raised_nice": self.raised_to,
                "threads": [{"id": tid, "nice": nice_of(tid)} for tid in ids],
            }
