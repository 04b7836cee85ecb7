"""`armfleet serve`'s server: uvicorn with our stop signals, and an exit status that tells.

uvicorn's own handlers stop on the first SIGINT, skip the application's shutdown on a second
one (where `latest` is saved), and re-raise the signal afterwards, so the exit status never said
whether saving worked. Here `service.core.process.stopping.StopSignals` owns both signals: the first
closes every stream with 1001 (going away, not 1012 restarting) and then asks uvicorn to stop, which
runs the application's shutdown (`Runtime.stop`: recordings finished, `latest` saved); a second
signal exits at once. The exit status is 1 when stopping left something unsaved.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
from collections.abc import Awaitable, Callable, Iterator

import uvicorn

from service import heap
from service.core.access import redact
from service.core.process.stopping import StopSignals
from service.runtime import Runtime
from service.settings import Settings

GOING_AWAY_S = 1.0  # how long closing the streams may hold up the stop


class _Server(uvicorn.Server):
    """uvicorn.Server whose signals are StopSignals' (see the module's docstring)."""

    def __init__(
        self,
        config: uvicorn.Config,
        before_exit: Callable[[], Awaitable[None]],
        on_quit: Callable[[], None] | None,
    ):
        super().__init__(config)
        self._before_exit = before_exit
        self._aio: asyncio.AbstractEventLoop | None = None
        self._going: asyncio.Future[None] | None = None
        self.signals = StopSignals(self._first_signal, on_quit)

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        self._aio = asyncio.get_running_loop()  # uvicorn calls this inside serve()
        self.signals.install()
        try:
            yield
        finally:
            self.signals.restore()  # and, unlike uvicorn, no signal raised again afterwards

    def _first_signal(self, sig: int) -> None:
        if self._aio is None:
            self.should_exit = True
        else:
            self._aio.call_soon_threadsafe(self._go_away)

    def _go_away(self) -> None:
        self._going = asyncio.ensure_future(self._close_then_exit())

    async def _close_then_exit(self) -> None:
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self._before_exit(), GOING_AWAY_S)
        self.should_exit = True


def serve_until_stopped(app: object, runtime: Runtime, settings: Settings) -> list[str]:
    """Serve `app` until SIGINT/SIGTERM; returns what stopping could not do (empty: all saved)."""
    heap.keep_large_blocks()  # big camera messages and frames: no page faults per message
    config = uvicorn.Config(
        app,  # type: ignore[arg-type]
        host=settings.server.host,
        port=settings.server.port,
        log_level=settings.server.log_level,
        ws_max_size=1 << 20,
        # Browsers offer permessage-deflate on every socket; deflating binary frames for each
        # viewer was the largest server cost of many viewers (bench section 9).
        ws_per_message_deflate=settings.server.ws_compression,
        timeout_graceful_shutdown=3,
    )
    # uvicorn prints paths with their query: a socket's ?token= or the page's ?lease= (after
    # Config, which sets its loggers up).
    redact.install("", "uvicorn", "uvicorn.access", "uvicorn.error")
    if (
        settings.engine.ray == "local"
    ):  # a private instance: it goes with us, even on a second signal
        from service.engines import ray_local

        _Server(config, runtime.going_away, ray_local.kill_local_instance).run()
        ray_local.stop_local_instance()  # the state is saved from it by now
    else:
        _Server(config, runtime.going_away, None).run()
    # Stopped and saved. The interpreter's exit would now run full garbage collections over
    # every object still alive (Warp's and MuJoCo Warp's kernels, the models): seconds of CPU
    # on each stop, for nothing. Frozen objects are left to the process's end.
    gc.freeze()
    return list(runtime.stop_problems)
