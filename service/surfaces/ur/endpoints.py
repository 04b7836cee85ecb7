"""Every world's UR ports, served by one event loop on a thread of its own.

Why one thread and asyncio: 32 worlds × 5 ports are 160 listening sockets and a few hundred
connections, mostly idle, and RTDE's 500 Hz sends are timers; one selector serves them all
for the cost of their descriptors (addresses.py). Why not the service's own event loop: RTDE
at 500 Hz to many clients is thousands of small writes a second, which the HTTP and WebSocket
surfaces should not queue behind. The sim thread only hands over the latest frame (surface.py).

Why the thread keeps the process's priority when the request thread gives the cores to the
ticks (core/process/priority.py): ur_rtde drops its connection 2.5 s after the last RTDE
package it got and then fails on a broken pipe. A thread a nice step below 32 client programs
on two cores can go that long without a turn; a late tick costs a fraction of real time, a
dropped connection costs the program.

With leases on, a world's ports accept a connection only while the world is lent: a
connection to a world that is not lent is closed at once, and when a lease ends (or the
world passes to another lease) every connection of that world is closed and its controller
state reset, checked every `_LEASE_POLL_S`. RTDE and the Dashboard carry no credentials:
anyone who can reach the address while it is lent drives that world (the guide says so).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import os
import resource
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from service.core.process import priority
from service.core.sim.safety import SafetyTable
from service.surfaces.ur import addresses
from service.surfaces.ur.dashboard import DashboardSession
from service.surfaces.ur.rtde_frame import Frame, FrameValues, FrameValuesCache
from service.surfaces.ur.rtde_pacer import Pacers
from service.surfaces.ur.rtde_session import RtdeSession
from service.surfaces.ur.script_ports import ScriptSession
from service.surfaces.ur.tcp_pose import ToolKinematics
from service.surfaces.ur.world_robot import WorldRobot

if TYPE_CHECKING:
    from service.surfaces.ur.motion import Motion

log = logging.getLogger("armfleet.ur")
_LEASE_POLL_S = 0.2
_PAYLOAD_POLL_S = 0.5


def _raise_descriptor_limit(worlds: int) -> None:
    """The soft open-file limit up to what the listeners want (addresses.descriptors_wanted);
    ValueError naming `ur_worlds` when the hard one cannot hold them."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = addresses.descriptors_wanted(worlds)
    if soft >= want:
        return
    addresses.check_hard_limit(worlds)
    resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
    log.info("UR ports: open-file limit raised from %d to %d", soft, want)


def _new_event_loop() -> asyncio.AbstractEventLoop:
    """uvloop's event loop where it is installed (uvicorn's `standard` extra), else asyncio's.

    Why: the pacers write thousands of small packages a second from this one thread. An
    asyncio transport writes through `socket.send`, which lets go of the GIL and takes it back
    on every call, so while the sim thread or the HTTP loop runs Python each write can wait
    for the GIL; uvloop writes in C with the GIL held, a pacer's round under one hold. 32 raw
    RTDE clients at 500 Hz on the shared 2-core box (bench section 32's receivers, eight runs
    of each alternated, load 10-35) got 198 packages a second per client on average, against
    140 with asyncio's loop."""
    try:
        import uvloop
    except ImportError:  # pragma: no cover (installed with uvicorn[standard])
        return asyncio.new_event_loop()
    return uvloop.new_event_loop()


class TickGaps:
    """The longest time between two ticks while RTDE streamed, and how many
    such times passed 0.1 s (the sink adds them on the sim thread; a reader may see one
    add late, never a torn value: two int/float assignments)."""

    SLOW_S = 0.1

    def __init__(self) -> None:
        self.longest_s = 0.0
        self.over = 0  # gaps of SLOW_S or more

    def add(self, gap: float) -> None:
        if gap > self.longest_s:
            self.longest_s = gap
        if gap >= self.SLOW_S:
            self.over += 1

    def status(self) -> dict[str, float | int]:
        return {"longest_s": round(self.longest_s, 4), "over_100ms": self.over}


class Endpoints:
    """The listeners of every UR world (see the module docstring)."""

    def __init__(
        self,
        worlds: dict[int, str],
        kin: ToolKinematics,
        owner_of: Callable[[int], str | None] | None,
        safety: SafetyTable,
        read_payloads: Callable[[list[int]], concurrent.futures.Future[Any]] | None = None,
    ) -> None:
        self.safety = safety  # the loop's safety modes (every world's controller reads them)
        safety.on_stop(self._stopped)  # whoever raised it: end the program, tell the clients
        self.robots = {w: WorldRobot(w, a, self) for w, a in worlds.items()}
        self.motion: Motion | None = None  # set by the surface at start
        self._values = FrameValuesCache(
            kin, lambda: None if self.motion is None else self.motion.tools
        )
        self._owner_of = owner_of  # None: leases off, every world always open
        self._read_payloads = read_payloads
        self.frame: Frame | None = None  # set by the sink (sim thread), read here
        self.payloads: dict[int, tuple[float, ...]] = {}
        self.streaming = 0  # started RTDE sessions (the sink asks for a snapshot per tick)
        self.tick_gaps = TickGaps()  # the sink's (sim thread), read by GET /v1/ur
        self.pacers = Pacers()  # one timer per RTDE frequency (UR thread)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._servers: list[asyncio.AbstractServer] = []
        self._tasks: list[asyncio.Task[None]] = []

    def start(self) -> None:
        """Bind every port of every world (ValueError, nothing left bound, when one fails)."""
        _raise_descriptor_limit(len(self.robots))
        ready: concurrent.futures.Future[None] = concurrent.futures.Future()
        self._thread = threading.Thread(
            target=self._run, args=(ready,), name="armfleet-ur", daemon=True
        )
        priority.start_at_process_priority(self._thread)  # see the module docstring
        try:
            ready.result(timeout=60)
        except Exception:
            self.stop()
            raise

    def _run(self, ready: concurrent.futures.Future[None]) -> None:
        loop = self._loop = _new_event_loop()
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._bind())
        except Exception as exc:
            ready.set_exception(exc)
            loop.run_until_complete(self._close())
            loop.close()
            return
        ready.set_result(None)
        loop.run_forever()
        loop.run_until_complete(self._close())
        loop.close()

    async def _bind(self) -> None:
        loop = asyncio.get_running_loop()
        for robot in self.robots.values():
            factories: dict[int, Callable[[], asyncio.Protocol]] = {
                addresses.RTDE_PORT: lambda r=robot: RtdeSession(r),
                addresses.PORTS["dashboard"]: lambda r=robot: DashboardSession(r),
            }
            for name, port in addresses.PORTS.items():
                if name != "dashboard":
                    factories[port] = lambda r=robot, p=port: ScriptSession(r, p)
            for port, factory in factories.items():
                try:
                    server = await loop.create_server(factory, robot.address, port)
                except OSError as exc:
                    raise ValueError(
                        f"ur_addresses: world {robot.world} cannot listen on "
                        f"{robot.address}:{port}: {exc.strerror or exc} (is the address on an "
                        "interface, and the port free?)"
                    ) from None
                self._servers.append(server)
        self._tasks.append(asyncio.create_task(self._watch()))

    async def _watch(self) -> None:
        """Leases (open/close worlds) and payloads (while RTDE streams), polled."""
        waited = 0.0
        while True:
            try:
                self._check_leases()
                if waited >= _PAYLOAD_POLL_S and self.streaming and self._read_payloads:
                    waited = 0.0
                    await self._refresh_payloads()
            except Exception:
                log.exception("UR watch failed")
            await asyncio.sleep(_LEASE_POLL_S)
            waited += _LEASE_POLL_S

    def _check_leases(self) -> None:
        if self._owner_of is None:
            return
        for robot in self.robots.values():
            owner = self._owner_of(robot.world) or None  # "" (being reset) counts as not lent
            if owner == robot.owner:
                continue
            if robot.owner is not None:
                robot.close_all(f"the lease of world {robot.world} ended")
            robot.owner, robot.open = owner, owner is not None
            robot.controller.reset()
            robot.longest_gap = 0.0

    async def _refresh_payloads(self) -> None:
        assert self._read_payloads is not None
        worlds = list(self.robots)
        read = await asyncio.wrap_future(self._read_payloads(worlds))
        self.payloads = {row["world"]: tuple(row["params"]["payload"]) for row in read["worlds"]}

    def values(self) -> FrameValues | None:
        """Every world's RTDE values at the latest frame (UR thread; once per tick)."""
        return self._values.get(self.frame)

    def begin_leases(self) -> None:
        """Leases on: every world starts closed until the first poll finds its lease."""
        for robot in self.robots.values():
            robot.open = False

    async def _close(self) -> None:
        for task in self._tasks:
            task.cancel()
        for server in self._servers:
            server.close()
        for robot in self.robots.values():
            robot.close_all("the service is stopping")
        for server in self._servers:
            with contextlib.suppress(Exception):
                await server.wait_closed()

    def _stopped(self, world: int, why: str) -> None:
        """A world was protective-stopped (any thread, any cause): its controller answers
        for it on the UR event loop (`WorldRobot.stopped`)."""
        loop, robot = self._loop, self.robots.get(world)
        if loop is not None and robot is not None and loop.is_running():
            loop.call_soon_threadsafe(robot.stopped, why)

    def stop(self) -> None:
        loop = self._loop
        if loop is not None and loop.is_running():
            loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(timeout=10)

    @property
    def thread_id(self) -> int | None:
        """The UR thread's id (the kernel's), once it runs."""
        return None if self._thread is None else self._thread.native_id

    def thread_nice(self) -> int | None:
        """The nice value the UR thread runs at (None: not running, or not Linux)."""
        tid = self._thread.native_id if self._thread is not None else None
        if tid is None or not hasattr(os, "getpriority"):
            return None
        try:
            return os.getpriority(os.PRIO_PROCESS, tid)
        except OSError:
            return None

    def thread_cpu_s(self) -> float | None:
        """CPU seconds the UR thread has used (None: not running, or no per-thread clock)."""
        thread = self._thread
        if thread is None or thread.ident is None or not hasattr(time, "pthread_getcpuclockid"):
            return None
        try:
            return round(time.clock_gettime(time.pthread_getcpuclockid(thread.ident)), 4)
        except OSError:  # the thread has ended
            return None

    def rtde_sent(self) -> int:
        """RTDE data packages sent to every world's clients since the service started."""
        return sum(r.rtde_sent() for r in self.robots.values())

    def status(self) -> list[dict[str, Any]]:
        """Each world's address, whether it accepts connections, its controller's modes, and
        the longest its RTDE clients went without a package since it was lent (or started)."""
        return [
            {
                "world": r.world,
                "address": r.address,
                "open": r.open,
                "clients": len(r.sessions),
                "robot_mode": r.controller.robot_mode.name,
                "safety_mode": r.controller.safety_mode.name,
                "program_state": r.controller.program.name,
                "rtde_longest_gap_s": round(r.longest_gap, 4),
            }
            for r in self.robots.values()
        ]
