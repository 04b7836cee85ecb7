"""Runtime: what one running service holds (engine, loop, control, hub, surfaces), start and stop.

The engine is built off the event loop because the first build compiles kernels (tens of
seconds cold); the HTTP server is up meanwhile, `/healthz` answers and `/readyz` says 503.
Surfaces are optional add-ons (ROS 2 bridge, Foxglove server, recorder, ...) that command through
`control` and listen through `loop.add_sink`; they start once the loop runs and stop before it.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import orjson

from service.core.access import ClientSlots
from service.core.control import Accepted, Control
from service.core.errors import ArmfleetError, Conflict, NotFound
from service.core.hub import StreamHub
from service.core.loop import SimLoop
from service.core.metrics import Metrics
from service.core.settings import Settings
from service.core.stopping import reclaim_stop_signals
from service.core.types import Batch
from service.persistence import provenance
from service.persistence.snapshots import LATEST, SnapshotStore, check_state_support

if TYPE_CHECKING:
    from service.persistence.recorder import Recorder

log = logging.getLogger("armfleet")


class Surface(Protocol):
    """An optional way in or out of the service, started with the loop and stopped before it."""

    name: str

    def start(self, runtime: Runtime) -> None: ...

    def stop(self) -> None: ...


def build_batch(s: Settings) -> Batch:
    """The engine the settings ask for: native MuJoCo on every core, or MuJoCo Warp (split over
    CPU cores when it pays). Imported here, so that the native engine never loads warp."""
    if s.engine == "mujoco":
        from service.engines.native import NativeBatch

        return NativeBatch(
            s.worlds,
            control_hz=s.control_hz,
            physics_dt=s.physics_dt,
            nthread=s.shards,
            device=s.device,
        )
    from service.engines.shards import ShardedBatch, auto_shards
    from service.engines.warp import WorldBatch

    shards = s.shards or auto_shards(s.worlds, s.device)
    kwargs = {"device": s.device, "control_hz": s.control_hz, "physics_dt": s.physics_dt}
    if s.ray:
        from service.engines import ray_local
        from service.engines.ray_shards import RayBatch  # imports Ray only when asked for

        with ray_local.starting():  # what Ray starts leaves stopping to us (core/stopping)
            return RayBatch(s.worlds, s.shards, address=s.ray, **kwargs)
    if shards > 1:
        return ShardedBatch(s.worlds, shards, **kwargs)
    return WorldBatch(s.worlds, **kwargs)


def optional_surfaces(s: Settings) -> list[Surface]:
    """The add-ons the settings ask for (imported only when asked for)."""
    out: list[Surface] = []
    if s.record is not None:
        from service.persistence.recorder import Recorder

        out.append(Recorder(s.record, s.record_worlds, s.record_rate, s.record_queue))
    if s.foxglove:
        from service.surfaces.foxglove_live import FoxgloveLive

        out.append(
            FoxgloveLive(
                s.host,
                s.foxglove_port,
                s.foxglove_worlds,
                s.foxglove_rate,
                commands=s.token is None,
            )
        )
    if s.ros2:
        from service.surfaces.ros.dds import DdsBridge

        out.append(DdsBridge(s.ros2_rate, s.ros2_worlds, s.ros2_network))
    return out


class Runtime:
    def __init__(self, settings: Settings, surfaces: tuple[Surface, ...] = ()):
        self.settings = settings
        self.loop: SimLoop | None = None
        self.control: Control | None = None
        self.hub: StreamHub | None = None
        self.surfaces: list[Surface] = [*surfaces, *optional_surfaces(settings)]
        self.error: str | None = None
        self.metrics = Metrics()
        self.slots = ClientSlots(settings.max_clients)  # shared by HTTP and every socket surface
        self._problems: list[str] = []
        self._watchdog: asyncio.Task[None] | None = None
        self.stop_problems: list[str] = []  # what `stop` could not save (the exit status)
        self._register_levels()
        self.snapshots = SnapshotStore(settings.data_dir)
        self.header: dict[str, object] = {}  # provenance.batch_header of the running batch

    @property
    def recorder(self) -> Recorder | None:
        """The recording that is running or last ran (None if there was none)."""
        from service.persistence.recorder import Recorder

        found = [x for x in self.surfaces if isinstance(x, Recorder)]
        return found[-1] if found else None

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
        health: Callable[[], list[str]] | None = getattr(self.loop.batch, "health", None)
        if health is not None:
            out += health()
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
        m.level(
            "armfleet_subscribers",
            "WebSocket stream subscribers",
            lambda: None if self.hub is None else self.hub.subscribers,
        )
        m.level("armfleet_clients", "clients being served now", lambda: self.slots.active)
        m.counter_level(
            "armfleet_frames_skipped",
            "state frames replaced by a newer one before a slow reader took them",
            lambda: None if self.hub is None else self.hub.frames_skipped,
        )
        m.counter_level(
            "armfleet_shard_restarts",
            "shard worker processes rebuilt after dying",
            lambda: getattr(self.loop.batch, "restarts", 0) if self.loop else None,
        )

    def _loop_attr(self, name: str) -> Any:
        return None if self.loop is None else getattr(self.loop, name)

    def _count_accepted(self, accepted: Accepted) -> None:
        self.metrics.command_accepted(accepted.source, accepted.kind, accepted.tick)

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
            batch = await asyncio.to_thread(build_batch, s)
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            log.exception("engine failed to start")
            return
        reclaim_stop_signals()  # building may have loaded a library that took them (Ray)
        self.header = provenance.batch_header(batch)
        if s.restore and not await asyncio.to_thread(self._restore_at_start, batch, s.restore):
            batch.close()
            return
        self.hub = StreamHub(asyncio.get_running_loop())
        loop = SimLoop(batch, s.mode, (self.hub,))
        self.control = Control(loop)
        self.control.add_listener(self._count_accepted)
        loop.add_tick_listener(self.metrics.on_tick)
        loop.start()
        self.loop = loop
        self._watchdog = asyncio.create_task(self._watch())
        for surface in self.surfaces:
            try:
                surface.start(self)
            except ArmfleetError as exc:  # e.g. --record's file full: its status says so
                log.error("%s did not start: %s", surface.name, exc)
        log.info(
            "armfleet ready at http://%s:%d (docs /docs): %d worlds on %s (%d shard%s), "
            "%d substeps of %.3f ms per %.0f Hz tick, mode %s; compile %.1f s, capture %.2f s%s",
            s.host,
            s.port,
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

    async def going_away(self) -> None:
        """Close every stream with 1001 (going away) before the server stops: clients learn
        that the service is stopping rather than restarting (uvicorn's own close says 1012)."""
        if self.hub is not None:
            await self.hub.close_all(1001, "service stopping")

    def _restore_at_start(self, batch: Batch, name: str) -> bool:
        """`--restore NAME` before the loop starts; False (and `error` set) if it cannot be.

        A missing `latest` only means there was no earlier run: the batch starts from home.
        """
        try:
            check_state_support(batch)
            state = self.snapshots.load(name, self.header)
            batch.set_state(state)
        except NotFound:
            if name == LATEST:
                log.warning("no snapshot latest in %s yet: starting at home", self.snapshots.dir)
                return True
            self.error = f"--restore {name}: no such snapshot in {self.snapshots.dir}"
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
        for surface in reversed(self.surfaces):
            try:
                surface.stop()
            except Exception:
                log.exception("surface %s failed to stop", surface.name)
                self.stop_problems.append(f"{surface.name} failed to stop")
        self.stop_problems += unfinished_recordings(self.surfaces)
        if self.loop is not None:
            self.loop.stop()
            if self.settings.save_on_exit and self._can_save():
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
            info = self.snapshots.save(LATEST, self.loop.batch.get_state(), self.header)
            log.info("saved snapshot 'latest' at tick %d (%d bytes)", info.tick, info.size_bytes)
            return
        except ArmfleetError as exc:  # CannotWrite: the cause is in the message
            why = str(exc)
        except Exception as exc:
            log.exception("could not save snapshot 'latest'")
            why = f"{type(exc).__name__}: {exc}"
        log.error("could not save snapshot 'latest' in %s: %s", self.snapshots.dir, why)
        self.stop_problems.append(f"snapshot 'latest' not saved: {why}")


def unfinished_recordings(surfaces: list[Surface]) -> list[str]:
    """Why each recording among `surfaces` is not a complete file (stopped early, stuck)."""
    from service.persistence.recorder import Recorder

    return [
        f"recording {s.path} is incomplete: {s.status.error}"
        for s in surfaces
        if isinstance(s, Recorder) and s.status.error
    ]
