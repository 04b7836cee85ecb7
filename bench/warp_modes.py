"""Warp switches the CUDA replay bench (bench/replay_cuda.py) tries, kept here, not in the service.

* `enable()`: Warp's process-wide deterministic mode (`wp.config.deterministic = RUN_TO_RUN`, also
  set on the modules created at import). Float atomics then reduce in a fixed order and counter
  slots (contact and constraint rows) are assigned in thread order. A few MuJoCo Warp modules
  cannot be compiled that way (an array both accumulated into and written directly); those fall
  back to the default mode (`fallbacks`). Measured on an H100 with MuJoCo Warp 4.0.0: compiling
  every module so (62, on 16 threads) took most of 396 s, then the first step stopped in the convex
  collision kernel (`ccd_kernel`: "a thread called atomic_add() differently when Warp repeated
  the kernel to assign stable slot numbers"), so the service does not offer it.
* `prebuild()`: compile every module a tick uses at once on all cores. Warp compiles a module at
  the first launch of one of its kernels, so a cold first tick compiles ~60 modules one after the
  other. Here a throw-away batch is first built with launches that only note each kernel's module
  (MuJoCo Warp creates many modules when a step asks for a kernel variant, so they exist only
  once a step has been walked through; wp.capture_if/while bodies are walked once), then
  `wp.force_load` compiles those modules in parallel threads.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import time
from collections.abc import Callable, Iterator
from typing import Any

import warp as wp
from warp._src import context as _wp_context
from warp._src.deterministic import WarpDeterminismError

log = logging.getLogger("armfleet.bench.warp_modes")

_RUN_TO_RUN = wp.DeterministicMode.RUN_TO_RUN
_DEFAULT = wp.DeterministicMode.NOT_GUARANTEED
fallbacks: list[str] = []  # modules that stayed in the default mode
_enabled = False


def enable() -> None:
    """Compile every Warp module of this process in RUN_TO_RUN mode from now on (once)."""
    global _enabled
    if _enabled:
        return
    _enabled = True
    wp.config.deterministic = _RUN_TO_RUN  # modules created from now on
    for module in list(_wp_context.user_modules.values()):  # those created at import
        if module.options.get("deterministic") == _DEFAULT:
            module.options["deterministic"] = _RUN_TO_RUN
            module.mark_modified()
    _wp_context.Module.load = _load_or_fall_back(_wp_context.Module.load)


def _load_or_fall_back(load: Callable[..., Any]) -> Callable[..., Any]:
    """Module.load that builds a module Warp cannot make deterministic in the default mode."""

    @functools.wraps(load)
    def wrapper(self: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            return load(self, *args, **kwargs)
        except WarpDeterminismError as exc:
            if self.options.get("deterministic") == _DEFAULT:
                raise
            self.options["deterministic"] = _DEFAULT
            self.mark_modified()
            fallbacks.append(self.name)
            log.info("module %s stays in the default mode: %s", self.name, str(exc)[:200])
            return load(self, *args, **kwargs)

    return wrapper


@contextlib.contextmanager
def _noted_launches(seen: dict[str, Any]) -> Iterator[None]:
    """wp.launch and wp.launch_tiled note the kernel's module instead of running it; the
    device-side branches and loops (wp.capture_if / capture_while) walk each body once."""
    saved = (wp.launch, wp.launch_tiled, wp.capture_if, wp.capture_while)

    def note(kernel: Any, *args: Any, **kwargs: Any) -> None:
        seen[kernel.module.name] = kernel.module

    def branch(condition: Any, on_true: Any = None, on_false: Any = None, **kwargs: Any) -> None:
        kwargs.pop("stream", None)
        for body in (on_true, on_false):
            if callable(body):
                body(**kwargs)

    def loop(condition: Any, while_body: Any, **kwargs: Any) -> None:
        branch(condition, while_body, None, **kwargs)

    wp.launch, wp.launch_tiled, wp.capture_if, wp.capture_while = note, note, branch, loop
    try:
        yield
    finally:
        wp.launch, wp.launch_tiled, wp.capture_if, wp.capture_while = saved


def prebuild(device: str, walk: Callable[[], Any], workers: int | None = None) -> dict[str, Any]:
    """Walk `walk` (builds a throw-away batch) with noted launches, then compile the modules it
    used on `device` with `workers` threads (default: every core). Returns what it did; a walk
    that fails only costs the parallel compile (the batch then compiles as usual)."""
    seen: dict[str, Any] = {}
    t0 = time.perf_counter()
    try:
        with _noted_launches(seen):
            walk()
    except Exception as exc:  # the real build compiles as it goes
        log.warning(
            "prebuild walk failed (%s: %s); compiling as the tick runs", type(exc).__name__, exc
        )
        return {"modules": 0, "error": f"{type(exc).__name__}: {exc}"}
    workers = workers or os.cpu_count() or 1
    wp.force_load(device=device, modules=list(seen.values()), max_workers=workers)
    return {"modules": len(seen), "workers": workers, "seconds": round(time.perf_counter() - t0, 1)}
