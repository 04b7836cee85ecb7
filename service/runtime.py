"""Runtime: what one running service holds (engine, loop, control, hub, surfaces), start and stop.

The engine is built off the event loop because the first build compiles kernels (tens of
seconds cold); the HTTP server is up meanwhile, `/healthz` answers and `/readyz` says 503.
Surfaces are optional add-ons (ROS 2 bridge, Foxglove server, recorder, ...) that command through
`control` and listen through `loop.add_sink`; they start once the loop runs and stop before it.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING, Protocol

from service import provenance
from service.control import Control
from service.errors import Conflict, NotFound
from service.hub import StreamHub
from service.loop import SimLoop
from service.settings import Settings
from service.snapshots import LATEST, SnapshotStore, check_state_support
from service.types import Batch

if TYPE_CHECKING:
    from service.recorder import Recorder

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
        from service.native import NativeBatch

        return NativeBatch(
            s.worlds,
            control_hz=s.control_hz,
            physics_dt=s.physics_dt,
            nthread=s.shards,
            device=s.device,
        )
    from service.engine import WorldBatch
    from service.shards import ShardedBatch, auto_shards

    shards = s.shards or auto_shards(s.worlds, s.device)
    kwargs = {"device": s.device, "control_hz": s.control_hz, "physics_dt": s.physics_dt}
    if s.ray:
        from service.ray_shards import RayBatch  # imports Ray only when asked for

        return RayBatch(s.worlds, s.shards, address=s.ray, **kwargs)
    if shards > 1:
        return ShardedBatch(s.worlds, shards, **kwargs)
    return WorldBatch(s.worlds, **kwargs)


def optional_surfaces(s: Settings) -> list[Surface]:
    """The add-ons the settings ask for (imported only when asked for)."""
    out: list[Surface] = []
    if s.record is not None:
        from service.recorder import Recorder

        out.append(Recorder(s.record, s.record_worlds, s.record_rate, s.record_queue))
    if s.foxglove:
        from service.foxglove_live import FoxgloveLive

        out.append(FoxgloveLive(s.host, s.foxglove_port, s.foxglove_worlds, s.foxglove_rate))
    if s.ros2:
        from service.ros.dds import DdsBridge

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
        self.snapshots = SnapshotStore(settings.data_dir)
        self.header: dict[str, object] = {}  # provenance.batch_header of the running batch

    @property
    def recorder(self) -> Recorder | None:
        """The recording that is running or last ran (None if there was none)."""
        from service.recorder import Recorder

        found = [x for x in self.surfaces if isinstance(x, Recorder)]
        return found[-1] if found else None

    @property
    def ready(self) -> bool:
        return self.loop is not None

    async def start(self) -> None:
        s = self.settings
        try:
            batch = await asyncio.to_thread(build_batch, s)
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            log.exception("engine failed to start")
            return
        self.header = provenance.batch_header(batch)
        if s.restore and not await asyncio.to_thread(self._restore_at_start, batch, s.restore):
            batch.close()
            return
        self.hub = StreamHub(asyncio.get_running_loop())
        loop = SimLoop(batch, s.mode, (self.hub,))
        self.control = Control(loop)
        loop.start()
        self.loop = loop
        for surface in self.surfaces:
            surface.start(self)
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
        for surface in reversed(self.surfaces):
            try:
                surface.stop()
            except Exception:
                log.exception("surface %s failed to stop", surface.name)
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
        """Snapshot `latest` of the stopped batch; a failure is logged, never raised at exit."""
        assert self.loop is not None
        try:
            info = self.snapshots.save(LATEST, self.loop.batch.get_state(), self.header)
            log.info("saved snapshot 'latest' at tick %d (%d bytes)", info.tick, info.size_bytes)
        except Exception:
            log.exception("could not save snapshot 'latest' in %s", self.snapshots.dir)
