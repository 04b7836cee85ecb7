"""The UR surface: every world's controller ports (endpoints.py), the sink that hands RTDE the
latest tick, and `GET /v1/ur` (each world's address and controller state).

The sink runs on the sim thread: after every published snapshot it keeps it as the latest
`Frame`, with the position target's rate of change since the last one (RTDE's target_qd and
target_qdd), and it asks the loop for a snapshot at every tick while an RTDE client streams,
so that a 500 Hz stream of a 500 Hz world carries every tick. The event loop of the UR
thread reads that one reference. The robot's safety rules are the core's, on every world, UR
or not (core/commands/clearance_watch.py: a target into a fixed obstacle; torque_watch.py: a
joint held at its torque limit); a world they stop is told to its controller through the
safety table's `on_stop` (the program ends, the controller says STOPPED).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from fastapi import APIRouter

from service.core.access.callers import book_of
from service.core.access.policy import is_loopback
from service.core.commands import params
from service.core.sim.loop_types import SnapshotSink
from service.core.sim.types import Snapshot
from service.core.sim.worlds import world_list
from service.core.surface import ServiceFacts, SurfaceContext
from service.surfaces.ur import addresses
from service.surfaces.ur.endpoints import Endpoints
from service.surfaces.ur.motion import Motion
from service.surfaces.ur.rtde_outputs import Frame
from service.surfaces.ur.settings import UrSettings
from service.surfaces.ur.tcp_pose import ToolKinematics

log = logging.getLogger("armfleet.ur")


class UrSink(SnapshotSink):
    """Keeps the latest snapshot as RTDE's `Frame` (sim thread; see the module docstring)."""

    def __init__(
        self,
        endpoints: Endpoints,
        tick_dt: float,
        first: Snapshot,
    ) -> None:
        self._ep, self._dt = endpoints, tick_dt
        zero = np.zeros_like(first.target, dtype=np.float64)
        self._last = Frame(first, zero, zero, tick_dt)
        self._at: float | None = None  # the loop's time of the last tick while streaming
        endpoints.frame = self._last

    def wants_snapshot(self, now: float) -> bool:
        return self._ep.streaming > 0

    def at_rest(self, batch: Any, now: float) -> None:
        self._at = None  # time stopped: the wait for the next tick is no gap of the ticks

    def on_tick(self, batch: Any, now: float) -> None:
        """The time since the last tick while RTDE streams (`TickGaps`: GET /v1/ur), as the
        sim thread sees it: a tick held up for whatever reason (cores, the GIL, a lock) shows
        here, where a client's gap also counts the UR thread's own delays. Time stopped
        (`at_rest`: a pause, the end of a step burst) is no gap."""
        ep = self._ep
        if not ep.streaming:
            self._at = None
            return
        if self._at is not None:
            ep.tick_gaps.add(now - self._at)
        self._at = now

    def publish(self, snap: Snapshot) -> None:
        last = self._last
        ticks = snap.tick - last.snap.tick
        if ticks == 0:
            qd, qdd = last.target_qd, last.target_qdd
        elif ticks < 0:  # restored to an earlier tick: no rate of change to speak of
            qd = qdd = np.zeros_like(last.target_qd)
        else:
            dt = ticks * self._dt
            qd = (np.asarray(snap.target, dtype=np.float64) - last.snap.target) / dt
            qdd = (qd - last.target_qd) / dt
        self._last = Frame(snap, qd, qdd, self._dt)
        self._ep.frame = self._last


class UrSurface:
    """`armfleet serve --ur` (see the package docstring)."""

    name = "ur"

    def __init__(self, settings: UrSettings, facts: ServiceFacts) -> None:
        self.worlds = (
            world_list(settings.worlds, facts.worlds, "ur_worlds")
            if settings.worlds
            else list(range(facts.worlds))
        )
        self.addresses = addresses.assign(self.worlds, settings.addresses, facts.access)
        addresses.check_hard_limit(len(self.worlds))  # refused before the engine is built
        self._leases = facts.access.leases != "off"
        self.endpoints: Endpoints | None = None
        self._sink: UrSink | None = None
        self._ctx: SurfaceContext | None = None
        self.router = self._routes()

    def start(self, ctx: SurfaceContext) -> None:
        self._ctx = ctx
        loop = ctx.loop
        book = book_of(ctx.control)
        owner_of = book.owner if book is not None else None
        read = lambda worlds: loop.call(lambda b: params.read(b, worlds))  # noqa: E731
        kin = ToolKinematics(loop.batch.robot)
        ep = Endpoints(self.addresses, kin, owner_of, loop.safety, read)
        ep.motion = Motion(ctx.control, lambda: ep.frame)
        if owner_of is not None or self._leases:
            ep.begin_leases()
        self.endpoints = ep
        ep.start()
        if ep.thread_id is not None:  # raised with the engine, below it (engine_priority.py)
            loop.priority.add_companion(ep.thread_id)
        self._sink = UrSink(ep, loop.batch.tick_dt, loop.latest)
        loop.listeners.add_sink(self._sink)
        first, last = self.addresses[self.worlds[0]], self.addresses[self.worlds[-1]]
        log.info(
            "UR controllers of %d worlds: world %d at %s ... world %d at %s (RTDE %d, "
            "Dashboard %d, script ports 30001-30003; %d listening descriptors)%s",
            len(self.worlds),
            self.worlds[0],
            first,
            self.worlds[-1],
            last,
            addresses.RTDE_PORT,
            addresses.PORTS["dashboard"],
            addresses.descriptors(len(self.worlds)),
            "; leases on: a world's ports open only while it is lent" if self._leases else "",
        )
        if not all(is_loopback(a) for a in self.addresses.values()):
            log.warning(
                "UR ports listen off loopback: RTDE and the Dashboard carry no token, so "
                "anyone who reaches an address drives that world%s",
                " while it is lent" if self._leases else "",
            )

    def stop(self) -> None:
        if self._ctx is not None and self._sink is not None:
            self._ctx.loop.listeners.remove_sink(self._sink)
        if self.endpoints is not None:
            self.endpoints.stop()

    def status(self) -> dict[str, Any]:
        ep = self.endpoints
        return {
            "ports": {**addresses.PORTS, "rtde": addresses.RTDE_PORT},
            "leases": self._leases,
            "thread_nice": None if ep is None else ep.thread_nice(),
            # what the UR thread used, for how many RTDE packages; the ticks' longest gap
            # while RTDE streamed (bench section 32 reads these before and after a run)
            "thread_cpu_s": None if ep is None else ep.thread_cpu_s(),
            "rtde_packages_sent": 0 if ep is None else ep.rtde_sent(),
            "tick_gaps": None if ep is None else ep.tick_gaps.status(),
            # what the threads that step the worlds run at (core/process/engine_priority.py)
            "engine_priority": None if self._ctx is None else self._ctx.loop.priority.status(),
            "worlds": ep.status()
            if ep is not None
            else [{"world": w, "address": a} for w, a in self.addresses.items()],
        }

    def _routes(self) -> APIRouter:
        router = APIRouter()

        @router.get(
            "/v1/ur",
            tags=["ur"],
            summary="Each world's UR controller: its address, whether it accepts connections "
            "(leases), robot mode, safety mode and program state",
        )
        async def ur_status() -> dict[str, Any]:
            return self.status()

        return router
