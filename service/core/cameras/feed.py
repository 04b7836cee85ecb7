"""CameraFeed: pictures of the asked worlds and camera, taken only when someone asks.

A picture is two steps. On the loop's thread, between two ticks, the engine hands over the
asked worlds' positions (`Renderable.render_state`: one small copy, served like any other
request through `SimLoop.call`), so the picture shows exactly one tick. Then the renderer
draws them on a thread of its own, beside the stepping: the loop pays the copy, the drawing
costs a core of its own where there is one. Requests are drawn one after the other (one
render batch), and counted for /metrics.

The renderer (service/engines/camera_render.py) is handed in by the runtime: the core only
knows it through `ImageRenderer`.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from service.core.cameras.catalog import CameraSpec
from service.core.errors import Conflict, NotFound, Unavailable
from service.core.sim.batch import Batch, Renderable
from service.core.sim.loop import SimLoop


class ImageRenderer(Protocol):
    """Draws given world states (service/engines/camera_render.py's BatchRenderer)."""

    cameras: dict[str, CameraSpec]

    def warm(self) -> float: ...

    def render(self, qpos: np.ndarray, camera: str) -> Any:
        """An object with `rgb`, `depth` and `seg` arrays (None for an output not drawn)."""
        ...

    def launch(self, qpos: np.ndarray, camera: str) -> Any:
        """`render`, started: an object whose `result()` waits for what `render` returns."""
        ...


@dataclass(frozen=True)
class Shot:
    """What one camera saw in some worlds at one tick (arrays as `Images` in camera_render)."""

    tick: int
    camera: CameraSpec
    worlds: np.ndarray  # (k,) world ids, in the order of the images
    rgb: np.ndarray | None
    depth: np.ndarray | None
    seg: np.ndarray | None

    def image(self, output: str) -> np.ndarray:
        """The (k, h, w[, 3]) array of `output` (rgb, depth, seg); Conflict if not drawn."""
        arr = getattr(self, output)
        if arr is None:
            raise Conflict(
                f"camera {self.camera.name!r} does not draw {output} (it draws "
                f"{', '.join(self.camera.outputs)}; see --cameras)",
                "query.image",
            )
        return arr

    def only(self, worlds: np.ndarray, rows: slice | np.ndarray | None = None) -> Shot:
        """This picture cut down to `worlds` (among this one's); `rows`, where they lie, is
        found when not given. A view where they are consecutive rows."""
        at = rows_of(self.worlds, worlds) if rows is None else rows
        cut = (None if a is None else a[at] for a in (self.rgb, self.depth, self.seg))
        return Shot(self.tick, self.camera, worlds, *cut)


class CameraFeed:
    """The service's cameras: the specs served, and pictures on request."""

    def __init__(
        self,
        loop: SimLoop,
        specs: list[CameraSpec],
        build: Callable[[], ImageRenderer],
        at_start: bool = True,
    ) -> None:
        """`build` makes the renderer on the render thread: now (`at_start`), else when the
        feed is first `open`ed (a picture or the camera list asked)."""
        self.loop = loop
        self.specs = {s.name: s for s in specs}
        self.renders = 0  # render calls (one per request, whatever its number of worlds)
        self.images = 0  # images drawn (worlds x requests)
        self.render_seconds = 0.0  # wall time spent drawing
        self.state_seconds = 0.0  # wall time the loop's thread spent handing over states
        self.warm_s: float | None = None  # seconds the first draw of every camera took
        self.streams_direct = 0  # streams whose socket was taken over (service/api/ws_bulk.py)
        self.streams: set[Any] = set()  # open streams (`async close(code, reason)`): going away
        self.error: str | None = None
        self._lock = threading.Lock()
        self._waiting: dict[str, list[tuple[np.ndarray, concurrent.futures.Future[Shot]]]] = {}
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="armfleet-render")
        self._collect = concurrent.futures.ThreadPoolExecutor(
            1, thread_name_prefix="armfleet-pixels"
        )
        self._make = build
        self._renderer: concurrent.futures.Future[ImageRenderer] | None = None
        self.at_start = at_start
        if at_start:
            self.open()  # off every hot path: the render thread builds it

    def open(self) -> concurrent.futures.Future[ImageRenderer]:
        """The renderer, being built or built (the build starts on the first call). Pictures
        asked meanwhile wait for it on the render thread, which builds before it draws."""
        with self._lock:
            if self._renderer is None and self.specs:
                self._renderer = self._pool.submit(self._build, self._make)
            return self._renderer or _no_cameras()

    def _build(self, build: Callable[[], ImageRenderer]) -> ImageRenderer:
        try:
            renderer = build()
            self.warm_s = renderer.warm()
            return renderer
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            raise

    @property
    def available(self) -> bool:
        return bool(self.specs) and isinstance(self.loop.batch, Renderable)

    def spec(self, name: str) -> CameraSpec:
        """The served camera `name`; NotFound naming the cameras there are."""
        if name not in self.specs:
            have = (
                ", ".join(self.specs)
                or "none (the scene has no camera, or --cameras turned all off)"
            )
            raise NotFound(f"no camera {name!r}; cameras: {have}", "camera")
        return self.specs[name]

    def want(self, name: str, output: str) -> CameraSpec:
        """The served camera `name`, checked to draw `output`; NotFound or Conflict naming it."""
        spec = self.spec(name)
        if output not in spec.outputs:
            raise Conflict(
                f"camera {name!r} does not draw {output} (it draws {', '.join(spec.outputs)}; "
                "see --cameras)",
                "query.image",
            )
        return spec

    def shoot(self, worlds: np.ndarray, camera: str) -> concurrent.futures.Future[Shot]:
        """A picture of `worlds` (valid ids) by `camera`, at the next tick boundary.

        Requests for one camera that wait for the same tick boundary are drawn together: one
        state hand-over and one render of the worlds they ask between them, each request then
        given its own worlds (eight readers of a 2,048-world share each cost one render of
        16,384 worlds, not eight renders of 2,048)."""
        out, first = self._enqueue(worlds, camera)
        if first:  # the others ride along with this one's hand-over
            self._hand_over(camera)
        return out

    async def shoot_async(self, worlds: np.ndarray, camera: str) -> Shot:
        return await asyncio.wrap_future(self.shoot(worlds, camera))

    def _enqueue(
        self, worlds: np.ndarray, camera: str
    ) -> tuple[concurrent.futures.Future[Shot], bool]:
        """A request among those waiting for `camera`; True when it is the first (it hands
        the state over for all of them)."""
        self.spec(camera)
        if not isinstance(self.loop.batch, Renderable):
            raise Conflict("this engine cannot hand its state to the cameras", "camera")
        renderer = self.open()
        if renderer.done() and renderer.exception() is not None:
            raise Unavailable(self.error or "the cameras failed to start")
        if not renderer.done() and self.at_start:
            raise Unavailable("the cameras are starting (compiling kernels)")
        out: concurrent.futures.Future[Shot] = concurrent.futures.Future()
        with self._lock:
            group = self._waiting.setdefault(camera, [])
            group.append((np.asarray(worlds, dtype=np.int64), out))
            return out, len(group) == 1

    def _hand_over(self, camera: str) -> None:
        """Ask the loop for the state of the worlds waiting for `camera`."""
        spec = self.specs[camera]
        taken = self.loop.call(lambda batch: self._take(batch, camera))
        taken.add_done_callback(lambda got: self._drawn_later(got, spec))

    def _take(self, batch: Batch, camera: str) -> tuple[int, np.ndarray, np.ndarray, list] | None:
        """On the loop's thread: the state of every world the waiting requests ask (None, and
        every request failed, when the engine cannot hand it over)."""
        t0 = time.perf_counter()
        with self._lock:
            group = self._waiting.pop(camera, [])
        if not group:
            return None
        try:
            parts = [g[0] for g in group]
            ids = parts[0] if len(parts) == 1 else np.concatenate(parts)
            if len(ids) > 1 and not np.all(ids[1:] > ids[:-1]):  # sorted and distinct: as is
                ids = np.unique(ids)
            assert isinstance(batch, Renderable)
            state = batch.tick, ids, batch.render_state(ids), group
        except Exception as exc:
            for _, out in group:
                _fail(out, exc)
            return None
        with self._lock:
            self.state_seconds += time.perf_counter() - t0
        return state

    def _drawn_later(self, got: concurrent.futures.Future, spec: CameraSpec) -> None:
        if got.exception() is not None:  # the loop never ran the hand-over (stopping)
            with self._lock:
                group = self._waiting.pop(spec.name, [])
            for _, out in group:
                _fail(out, got.exception())  # type: ignore[arg-type]
            return
        if got.result() is None:
            return
        try:
            self._pool.submit(self._draw, *got.result(), spec)
        except RuntimeError as exc:  # closed meanwhile
            for _, out in got.result()[3]:
                _fail(out, Unavailable(f"cameras stopped: {exc}"))

    def _draw(
        self,
        tick: int,
        ids: np.ndarray,
        qpos: np.ndarray,
        group: list[tuple[np.ndarray, concurrent.futures.Future[Shot]]],
        spec: CameraSpec,
    ) -> None:
        """On the render thread: start the drawing, and hand the rest (waiting for the pixels
        to reach the host) to the collecting thread, so that the next picture's drawing is
        queued on the device while this one's pixels come over."""
        group = [(w, out) for w, out in group if out.set_running_or_notify_cancel()]
        if not group:
            return
        t0 = time.perf_counter()
        try:
            pending = self.open().result().launch(qpos, spec.name)
        except BaseException as exc:
            for _, out in group:
                out.set_exception(exc)
            return
        self._collect.submit(self._collected, t0, tick, ids, pending, group, spec)

    def _collected(
        self,
        t0: float,
        tick: int,
        ids: np.ndarray,
        pending: Any,
        group: list[tuple[np.ndarray, concurrent.futures.Future[Shot]]],
        spec: CameraSpec,
    ) -> None:
        try:
            images = pending.result()
            took = time.perf_counter() - t0
            with self._lock:
                self.renders += 1
                self.images += len(ids)
                self.render_seconds += took
        except BaseException as exc:
            for _, out in group:
                out.set_exception(exc)
            return
        whole = Shot(tick, spec, ids, images.rgb, images.depth, images.seg)
        for worlds, out in group:
            out.set_result(whole.only(worlds))

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._collect.shutdown(wait=True, cancel_futures=True)


def _fail(out: concurrent.futures.Future[Shot], exc: BaseException) -> None:
    """Fail a request unless its asker gave up on it meanwhile (cancelled: nothing to tell)."""
    if out.cancelled():
        return
    with contextlib.suppress(concurrent.futures.InvalidStateError):
        out.set_exception(exc)


def rows_of(drawn: np.ndarray, worlds: np.ndarray) -> slice | np.ndarray:
    """Where `worlds` lie among the sorted `drawn` ids: a slice (a view, no copy) when they are
    a run of consecutive rows in order, else the row indices."""
    at = np.searchsorted(drawn, worlds)
    if len(at) and at[-1] - at[0] == len(at) - 1 and np.all(np.diff(at) == 1):
        return slice(int(at[0]), int(at[-1]) + 1)
    return at


def _no_cameras() -> concurrent.futures.Future[ImageRenderer]:
    """What `open` gives when no camera is served: a future failed with NotFound."""
    done: concurrent.futures.Future[ImageRenderer] = concurrent.futures.Future()
    done.set_exception(NotFound("no camera is served (see --cameras)", "camera"))
    return done
