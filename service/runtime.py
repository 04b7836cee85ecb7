"""Runtime: what one running service holds (engine, loop, control, hub, surfaces), start and stop.

The engine is built off the event loop because the first build compiles kernels (tens of
seconds cold); the HTTP server is up meanwhile, `/healthz` answers and `/readyz` says 503.
Surfaces (the ROS bridge, rosbridge, the Foxglove server: surfaces/registry.py) and persistence
(snapshots and recordings: persistence/service.py) get a `SurfaceContext` once the loop runs and
stop before it; this module names no surface.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

import orjson

from service.core.access.callers import Gate
from service.core.access.lease_metrics import LeaseCollector
from service.core.access.leases import LeaseBook
from service.core.access.policy import ClientSlots
from service.core.access.rates import RateLimiter
from service.core.cameras.feed import CameraFeed
from service.core.commands.control import Accepted, Control
from service.core.commands.safety_watches import watch_safety
from service.core.errors import ArmfleetError, Conflict, NotFound
from service.core.metrics import Metrics
from service.core.process import priority
from service.core.process.stopping import reclaim_stop_signals
from service.core.sim.batch import Batch, Supervised
from service.core.sim.command_share import REQUESTS_NICE
from service.core.sim.loop import SimLoop
from service.core.sim.physics import solver_name
from service.core.sim.randomizations import Randomized
from service.core.sim.types import Mode
from service.core.streams.hub import StreamHub
from service.core.surface import Finishing, SurfaceContext, Watched
from service.engines.cameras import camera_feed
from service.engines.choice import build_batch, check_devices
from service.persistence import provenance
from service.persistence.service import Persistence
from service.persistence.snapshots import LATEST, check_state_support
from service.settings import Settings
from service.surfaces.registry import build_surfaces

log = logging.getLogger("armfleet")
LEASE = "lease"  # the source of the resets that start and end leases


class Runtime:
    def __init__(self, settings: Settings):
        self.settings = settings
        check_devices(settings.cameras.device)  # ValueError naming the setting, before serving
        self.loop: SimLoop | None = None
        self.control: Control | None = None
        self.hub: StreamHub | None = None
        # Before the surfaces: `--record`'s file is opened here, so one that cannot be written
        # stops the start before anything is built (CannotWrite, raised by create_app).
        self.persistence = Persistence(settings.persistence)
        self.cameras: CameraFeed | None = None  # built with the loop (service/core/cameras/feed)
        self.surfaces = build_surfaces(settings)
        self.error: str | None = None
        self.metrics = Metrics()
        # shared by HTTP and every socket surface
        self.slots = ClientSlots(settings.access.max_clients)
        self._problems: list[str] = []
        self._watchdog: asyncio.Task[None] | None = None
        self.stop_problems: list[str] = []  # what `stop` could not save (the exit status)
        self._restored_randomized: dict[int, Randomized] = {}  # `--restore`'s randomisations
        self._register_levels()
        self.header: dict[str, object] = {}  # provenance.batch_header of the running batch
        self.requests_nice: int | None = None  # the event loop thread's nice under ticks first
        self.leases: LeaseBook | None = None  # worlds lent (service.core.access.leases); None: off
        self.metrics.registry.register(LeaseCollector(lambda: self.control and self.control.gate))

    @property
    def ready(self) -> bool:
        return self.loop is not None and not self.problems()

    def problems(self) -> list[str]:
        """Why the service is not ready now: starting, engine failed, tick failing, shard lost."""
        if self.loop is None:
            return [self.error or "starting (compiling kernels)"]
        out = []
        if self.loop.failure:
            out.append(f"ticks are failing: {self.loop.failure}")
        if isinstance(self.loop.batch, Supervised):
            out += self.loop.batch.health()
        for surface in self.surfaces:  # a supervised child that is down (the ROS 2 node)
            if isinstance(surface, Watched):
                out += surface.problems()
        return out

    async def _watch(self, period: float = 0.1) -> None:
        """Notice problems between requests: tell subscribers and the log when they change."""
        while True:
            await asyncio.sleep(period)
            try:
                now = self.problems()
            except Exception:
                log.exception("health check failed")
                continue
            if now != self._problems:
                self._problems = now
                status = {"op": "status", "ready": not now, "problems": now}
                if self.hub is not None:
                    self.hub.broadcast(orjson.dumps(status))
                if now:
                    log.warning("not ready: %s", "; ".join(now))
                else:
                    log.warning("ready again")

    def _register_levels(self) -> None:
        m = self.metrics
        m.level("armfleet_ready", "1 when ready for commands", lambda: float(self.ready))
        m.level("armfleet_tick", "control ticks completed", lambda: self._loop_attr("tick"))
        m.level(
            "armfleet_realtime_factor",
            "simulated seconds per wall second over the last second",
            lambda: self._loop_attr("stats").realtime_factor if self.loop else None,
        )
        m.level(
            "armfleet_ticks_per_second",
            "control ticks per wall second over the last second",
            lambda: self._loop_attr("stats").ticks_per_s if self.loop else None,
        )
        m.counter_level(
            "armfleet_engine_step_seconds",
            "wall time the engine spent stepping (the rest of armfleet_tick_duration_seconds_sum "
            "is the loop's own work: commands, snapshots, frames)",
            lambda: self._loop_attr("engine_seconds"),
        )
        m.counter_level(
            "armfleet_engine_capture_seconds",
            "wall time spent capturing the tick's graph, at build and since (a capture holds "
            "the tick boundary that snapshots, recordings and reads wait for)",
            lambda: None if self.loop is None else self.loop.batch.capture_s,
        )
        m.level(
            "armfleet_subscribers",
            "WebSocket stream subscribers",
            lambda: None if self.hub is None else self.hub.subscribers,
        )
        m.level("armfleet_clients", "clients being served now", lambda: self.slots.active)
        share = lambda attr: None if self.loop is None else getattr(self.loop.share, attr)  # noqa: E731
        m.level(
            "armfleet_command_budget_seconds",
            "ticks first: event-loop seconds commands may take per real-time tick now",
            lambda: share("budget_s"),
        )
        m.counter_level(
            "armfleet_command_waits",
            "ticks first: commands that waited for a later tick's budget",
            lambda: share("waits"),
        )
        m.counter_level(
            "armfleet_commands_busy",
            "ticks first: commands refused for finding no turn within --command-wait-s",
            lambda: share("busy"),
        )
        m.counter_level(
            "armfleet_late_ticks",
            "real-time ticks that started late (over pace.LATE_S behind: 50 ms)",
            lambda: share("late_ticks"),
        )
        m.counter_level(
            "armfleet_frames_skipped",
            "state frames replaced by a newer one before a slow reader took them",
            lambda: None if self.hub is None else self.hub.frames_skipped,
        )
        m.counter_level(
            "armfleet_streams_direct",
            "binary state streams written by a thread of their own, without copies",
            lambda: None if self.hub is None else self.hub.streams_direct,
        )
        m.counter_level(
            "armfleet_shard_restarts",
            "shard worker processes rebuilt after dying",
            self._restarts,
        )
        self._register_cameras()

    def _register_cameras(self) -> None:
        for name, attr, help_text in (
            ("armfleet_camera_renders", "renders", "camera renders (one per request or frame)"),
            ("armfleet_camera_images", "images", "camera images drawn (worlds x renders)"),
            ("armfleet_camera_render_seconds", "render_seconds", "wall time spent drawing"),
            (
                "armfleet_camera_streams_direct",
                "streams_direct",
                "camera streams written by a thread of their own, without copies",
            ),
            (
                "armfleet_camera_state_seconds",
                "state_seconds",
                "wall time the sim thread spent handing world states to the cameras",
            ),
            (
                "armfleet_camera_gave_way",
                "gave_way",
                "stream pictures not drawn because the ticks ran late (ticks first)",
            ),
        ):
            self.metrics.counter_level(
                name,
                help_text,
                lambda a=attr: None if self.cameras is None else getattr(self.cameras, a),
            )

    def _restarts(self) -> float | None:
        if self.loop is None:
            return None
        return self.loop.batch.restarts if isinstance(self.loop.batch, Supervised) else 0

    def _loop_attr(self, name: str) -> Any:
        return None if self.loop is None else getattr(self.loop, name)

    def _count_accepted(self, accepted: Accepted) -> None:
        self.metrics.command_accepted(
            accepted.source, accepted.kind, accepted.tick, len(accepted.worlds)
        )

    async def start(self) -> None:
        """Build the engine and start everything; a failure is kept in `error` (see /readyz)."""
        try:
            await self._start()
        except Exception as exc:  # never leave /readyz saying "starting" forever
            self.error = f"{type(exc).__name__}: {exc}"
            log.exception("service failed to start")

    async def _start(self) -> None:
        s = self.settings
        try:
            batch = await asyncio.to_thread(build_batch, s.engine, s.sim, s.cameras.device)
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            log.exception("engine failed to start")
            return
        reclaim_stop_signals()  # building may have loaded a library that took them (Ray)
        self.header = provenance.batch_header(batch)
        own = batch.robot.own  # a user's cell: say what of its step options armfleet replaced
        solver = solver_name(batch.robot.mjm)  # the engine's, as configured
        line = own.told(batch.control_hz, s.sim.physics_dt, solver) if own else None
        if s.sim.scene is not None and line:
            log.warning("%s", line)
        restore = s.persistence.restore
        if restore and not await asyncio.to_thread(self._restore_at_start, batch, restore):
            batch.close()
            return
        loop = SimLoop(batch, s.sim.mode, priority=s.sim.engine_priority)
        loop.share.enabled, loop.share.max_wait_s = s.sim.ticks_first, s.sim.command_wait_s
        loop.randomizations.replace(self._restored_randomized)
        self.control = Control(loop)
        watch_safety(self.control)  # protective stops: into a fixed obstacle, at a torque limit
        # Packed JSON frames say where each world's trajectory is (the manager's briefs) and
        # each world's safety mode (the loop's table), as a snapshot's frame does.
        self.hub = hub = StreamHub(
            asyncio.get_running_loop(), self.control.trajectories, loop.safety
        )
        loop.listeners.add_sink(hub)
        loop.listeners.add_restore_listener(lambda _tick, _state, _name: hub.restored())
        self.control.add_listener(self._count_accepted)
        self._lend(batch.nworld)
        loop.listeners.add_tick_listener(self.metrics.on_tick)
        self.cameras = camera_feed(loop, s.cameras)
        if self.cameras.at_start:  # on a GPU (service/engines/cameras.py)
            # Built and warmed before the first tick: its kernels compiled or loaded, its render
            # contexts made. Built beside the ticks, its compile (mujoco_warp's render and BVH
            # modules, which `setup` did not compile before) slowed the first service run after
            # `armfleet setup` to 0.08x of the next (16,384 worlds, two H200s, issue 39).
            await self.cameras.warmed()
        loop.start()
        if s.sim.ticks_first and loop.mode is Mode.REALTIME:
            # the ticks' threads (started above) keep the first claim on the cores; not in a
            # service started fast or paused, whose engine may take every core (a nice value
            # cannot be taken back without privileges, so it stays if the mode changes later)
            self.requests_nice = priority.lower_this_thread(REQUESTS_NICE)
        self.loop = loop
        self._watchdog = asyncio.create_task(self._watch())
        ctx = SurfaceContext(
            loop, self.control, self.hub, s.access, self.slots, self.metrics, self.cameras
        )
        self.surfaces.start(ctx)
        self.persistence.start(ctx)
        log.info(
            "armfleet ready at http://%s:%d (docs /docs): %d worlds on %s (%d shard%s), "
            "%d substeps of %.3f ms per %.0f Hz tick, mode %s; compile %.1f s, capture %.2f s%s",
            s.server.host,
            s.server.port,
            batch.nworld,
            batch.device_name,
            batch.shards,
            "" if batch.shards == 1 else "s",
            batch.substeps,
            batch.physics_dt * 1e3,
            batch.control_hz,
            loop.mode.value,
            batch.compile_s,
            batch.capture_s,
            "" if batch.captured else f" (NOT captured: {batch.capture_error})",
        )

    def _lend(self, nworld: int) -> None:
        """The LeaseBook and the Gate Control checks every caller's commands with (leases on).
        Leases live in memory only: every lease ends when the service stops (see leases)."""
        s, control = self.settings.access, self.control
        if s.leases == "off" or control is None:
            return
        reset_at = {"both": ("start", "end"), "none": ()}.get(s.lease_reset, (s.lease_reset,))
        self.leases = LeaseBook(
            nworld, lambda worlds: control.reset(worlds, LEASE), reset_at, s.lease_max_ttl_s
        )
        # A lease gets the rate of one connection, over all its connections together.
        bucket = lambda: RateLimiter(s.command_rate, s.command_burst)  # noqa: E731
        control.gate = Gate(s, self.leases, nworld, bucket)

    async def going_away(self) -> None:
        """Close every stream with 1001 (going away) before the server stops: clients learn
        that the service is stopping rather than restarting (uvicorn's own close says 1012)."""
        if self.hub is not None:
            await self.hub.close_all(1001, "service stopping")
        if self.cameras is not None:
            for stream in list(self.cameras.streams):
                await stream.close(1001, "service stopping")

    def _restore_at_start(self, batch: Batch, name: str) -> bool:
        """`--restore NAME` before the loop starts; False (and `error` set) if it cannot be.

        A missing `latest` only means there was no earlier run: the batch starts from home.
        """
        try:
            check_state_support(batch)
            state = self.persistence.snapshots.load(name, self.header)
            batch.set_state(state)
            self._restored_randomized = state.randomized  # for the loop's book
        except NotFound:
            if name == LATEST:
                log.warning(
                    "no snapshot latest in %s yet: starting at home", self.persistence.snapshots.dir
                )
                return True
            self.error = f"--restore {name}: no such snapshot in {self.persistence.snapshots.dir}"
        except Exception as exc:  # Conflict (other model, size, corrupt), ValueError
            self.error = f"--restore {name}: {exc}"
        else:
            log.info("restored snapshot %r at tick %d", name, state.tick)
            return True
        log.error("%s", self.error)
        return False

    def stop(self) -> None:
        """Stop surfaces (recordings are finished), the loop, save `latest`, close the engine.

        What could not be saved is logged and kept in `stop_problems`, never raised: the
        engine is closed whatever happened.
        """
        if self._watchdog is not None:
            self._watchdog.cancel()
        self.persistence.stop()
        self.stop_problems += self.persistence.unfinished()
        self.surfaces.stop()
        if self.leases is not None:
            self.leases.stop()
        for surface in self.surfaces:
            if isinstance(surface, Finishing):
                self.stop_problems += surface.unfinished()
        if self.cameras is not None:
            self.cameras.close()
        if self.loop is not None:
            self.loop.stop()
            if self.hub is not None:
                self.hub.stop()
            if self.settings.persistence.save_on_exit and self._can_save():
                self._save_latest()
            self.loop.batch.close()

    def _can_save(self) -> bool:
        assert self.loop is not None
        try:
            check_state_support(self.loop.batch)
        except Conflict as exc:
            log.warning("not saving snapshot latest: %s", exc)
            return False
        return True

    def _save_latest(self) -> None:
        """Snapshot `latest` of the stopped batch; a failure is logged and kept, never raised."""
        assert self.loop is not None
        try:
            state = self.loop.state_door.state_of(self.loop.batch)
            info = self.persistence.snapshots.save(LATEST, state, self.header)
            log.info("saved snapshot 'latest' at tick %d (%d bytes)", info.tick, info.size_bytes)
            return
        except ArmfleetError as exc:  # CannotWrite: the cause is in the message
            why = str(exc)
        except Exception as exc:
            log.exception("could not save snapshot 'latest'")
            why = f"{type(exc).__name__}: {exc}"
        log.error("could not save snapshot 'latest' in %s: %s", self.persistence.snapshots.dir, why)
        self.stop_problems.append(f"snapshot 'latest' not saved: {why}")
