"""The CUDA streams of an engine that shares its device with the camera renderer.

A tick is a few hundred small kernels (one thread a world: 16,384 worlds fill a few percent of
an H100), a picture a few huge ones (16,384 64x64 images are 67 million rays). On streams of
equal priority the device works through whichever kernel came first: a tick queued behind a
picture waits for all of it, and the loop, which waits for its tick, falls behind while the
device idles between them. So the engine steps on a high-priority stream and the renderer
draws on a low-priority one: whenever a block of the picture ends, the scheduler gives its
place to the tick's blocks first. The tick keeps nearly its own pace and the picture takes
what the ticks leave of the device. (Measured on an H200, 16,384 worlds, realtime, pictures of
every world asked at 30 Hz: ticks held 60/s and pictures came at 25.9/s. The other way round,
ticks fell to 22/s and pictures to 19/s: a picture is handed its state at a tick boundary, so
starving the ticks starves the pictures too.)

Warp's current stream is one per device, not one per thread, so the engine's stream is made
the device's current stream once, when the engine is built (every launch, capture and copy
of the engine goes there without naming it), and the renderer makes its own stream current
only for its launches, in turns with the loop's thread (service/core/sim/device_turns.py).
"""

from __future__ import annotations

import warp as wp

from service.core.sim.device_turns import DeviceTurns

HIGH, LOW = -1, 0  # CUDA stream priorities as Warp takes them (a lower number goes first)


def engine_streams(device: wp.context.Device) -> DeviceTurns | None:
    """On CUDA: a high-priority stream of the engine's own, made the device's current stream,
    and the turns the renderer and the loop take to launch; None elsewhere."""
    if not device.is_cuda:
        return None
    wp.set_stream(wp.Stream(device, priority=HIGH), device=device, sync=True)
    return DeviceTurns()


def render_stream(device: wp.context.Device) -> wp.Stream:
    """A low-priority stream for the pictures (and their copies to the host)."""
    return wp.Stream(device, priority=LOW)
