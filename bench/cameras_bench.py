"""Section 29: cameras on the CPU: milliseconds per image, and a 10 Hz stream beside real time.

* per image: a paused service (warp engine, then native MuJoCo) with the wrist camera at
  128x96, then 320x240 (RGB + depth); `requests` asks of one world and of 16 worlds in one
  reply (GET /v1/cameras/wrist/images); the drawing time is the service's own
  armfleet_camera_render_seconds over armfleet_camera_images, the request time what the
  client waited (PNG encoding and HTTP included);
* streaming: a realtime service of 16 worlds; the loop's real-time factor over a window with
  nobody looking, then over a window while one WebSocket streams all 16 wrist cameras at
  10 Hz (JPEG), side by side in one run; frames received per second and the drawing share.

On a CUDA machine, ``--section 29 --device cuda`` runs the same on the GPU (the warp engine
and its renderer on the device; the native engine renders on the CPU); not measured yet.
Standalone: ``python -m bench.cameras_bench --quick``.
"""

from __future__ import annotations

import statistics
import threading
import time
from collections.abc import Callable
from typing import Any

import httpx

from bench import common
from bench.registry import Context, Result, section

SIZES = ("128x96", "320x240")
ENGINES = ("warp", "mujoco")


def _metrics(url: str) -> dict[str, float]:
    text = httpx.get(f"{url}/metrics", timeout=30).text
    return {
        x.split()[0]: float(x.split()[1])
        for x in text.splitlines()
        if x.startswith("armfleet_camera")
    }


def _ready(url: str) -> None:
    deadline = time.monotonic() + 900
    while not httpx.get(f"{url}/v1/cameras", timeout=30).json()["ready"]:
        if time.monotonic() > deadline:
            raise TimeoutError("cameras not ready in 900 s")
        time.sleep(0.5)


def _per_image(ctx: Context, engine: str, size: str, requests: int) -> dict[str, Any]:
    env = {"ARMFLEET_ENGINE": engine, "ARMFLEET_CAMERAS": f"wrist={size}:rgb+depth"}
    out: dict[str, Any] = {"engine": engine, "size": size}
    with ctx.serve(16, "paused", env) as srv, httpx.Client(base_url=srv.url, timeout=60) as c:
        _ready(srv.url)
        for label, path, params in (
            ("one", "/v1/worlds/0/cameras/wrist", {"format": "png"}),
            ("sixteen", "/v1/cameras/wrist/images", {"worlds": "0-15", "format": "png"}),
        ):
            c.get(path, params=params).raise_for_status()  # first request: nothing cold
            m0, waits = _metrics(srv.url), []
            for _ in range(requests):
                t0 = time.perf_counter()
                c.get(path, params=params).raise_for_status()
                waits.append(time.perf_counter() - t0)
            m1 = _metrics(srv.url)
            images = m1["armfleet_camera_images_total"] - m0["armfleet_camera_images_total"]
            drawn = (
                m1["armfleet_camera_render_seconds_total"]
                - m0["armfleet_camera_render_seconds_total"]
            )
            out[label] = {
                "ms_per_image": 1e3 * drawn / images,
                "request_ms_p50": 1e3 * statistics.median(waits),
                "images": images,
            }
    return out


def _stream(ctx: Context, engine: str, window_s: float) -> dict[str, Any]:
    from websockets.sync.client import connect

    env = {"ARMFLEET_ENGINE": engine}
    with ctx.serve(16, "realtime", env) as srv:
        _ready(srv.url)
        time.sleep(2.0)
        a = srv.get_info()
        time.sleep(window_s)
        b = srv.get_info()
        idle = common.rtf_between(a, b)
        frames, stop = [0], threading.Event()
        url = f"{srv.ws_url}/v1/ws/cameras?camera=wrist&worlds=0-15&rate=10&format=jpeg"

        def read() -> None:
            with connect(url, max_size=None) as ws:
                while not stop.is_set():
                    ws.recv(timeout=30)
                    frames[0] += 1

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        time.sleep(2.0)  # the stream settles
        m0, f0, a = _metrics(srv.url), frames[0], srv.get_info()
        time.sleep(window_s)
        m1, f1, b = _metrics(srv.url), frames[0], srv.get_info()
        stop.set()
        reader.join(timeout=30)
        streaming = common.rtf_between(a, b)
        wall = b[0] - a[0]
        drawn = (
            m1["armfleet_camera_render_seconds_total"] - m0["armfleet_camera_render_seconds_total"]
        )
        state = (
            m1["armfleet_camera_state_seconds_total"] - m0["armfleet_camera_state_seconds_total"]
        )
    return {
        "engine": engine,
        "rtf_idle": idle,
        "rtf_streaming": streaming,
        "frames_per_s": (f1 - f0) / wall,
        "draw_share": drawn / wall,  # of one core
        "sim_thread_ms_per_s": 1e3 * state / wall,
    }


@section(29, "cameras", devices=("cpu", "cuda"), default_on=("cpu",))
def cameras(ctx: Context) -> Result:
    """Cameras: ms per image, 16 wrist cameras at 10 Hz beside real time"""
    requests = ctx.pick(20, 5)
    window = ctx.pick(10.0, 5.0)
    per_image: list[dict[str, Any]] = []
    streams: list[dict[str, Any]] = []
    errors: dict[str, str] = {}

    def attempt(
        what: str,
        measure: Callable[[], dict[str, Any]],
        describe: Callable[[dict[str, Any]], str],
        into: list[dict[str, Any]],
    ) -> None:
        """One measurement into `into`, said (as `Context.each` does for sizes); a failure is
        kept in `errors` and loses only this one."""
        try:
            r = measure()
        except Exception as exc:
            errors[what] = f"{type(exc).__name__}: {exc}"
            ctx.say(f"  {what} FAILED: {exc}")
            return
        into.append(r)
        ctx.say(f"  {what}: {describe(r)}")

    for engine in ENGINES:
        for size in SIZES:
            attempt(
                f"{engine} {size}",
                lambda e=engine, s=size: _per_image(ctx, e, s, requests),
                lambda r: (
                    f"{r['one']['ms_per_image']:.1f} ms/image alone, "
                    f"{r['sixteen']['ms_per_image']:.1f} ms/image 16 at once"
                ),
                per_image,
            )
        attempt(
            f"{engine} stream",
            lambda e=engine: _stream(ctx, e, window),
            lambda s: (
                f"RTF {s['rtf_idle']:.3f} idle, {s['rtf_streaming']:.3f} streaming, "
                f"{s['frames_per_s']:.1f} frames/s"
            ),
            streams,
        )
    rows = [
        {
            "engine": r["engine"],
            "size": r["size"],
            "ms/image (1 world)": r["one"]["ms_per_image"],
            "ms/image (16 at once)": r["sixteen"]["ms_per_image"],
            "request p50 ms (1)": r["one"]["request_ms_p50"],
            "request p50 ms (16)": r["sixteen"]["request_ms_p50"],
        }
        for r in per_image
    ]
    rows += [
        {
            "engine": s["engine"],
            "size": "stream 16 x 128x96 @10 Hz",
            "RTF idle": s["rtf_idle"],
            "RTF streaming": s["rtf_streaming"],
            "frames/s": s["frames_per_s"],
            "draw share of a core": s["draw_share"],
            "sim thread ms/s": s["sim_thread_ms_per_s"],
        }
        for s in streams
    ]
    notes = [
        "ms/image: the service's drawing time per image (MuJoCo Warp's CPU renderer, one "
        "thread, RGB + depth); request: what a client waited, PNG encoding included",
        f"device: {ctx.device}" + ("" if ctx.cuda else "; GPU not measured in this run"),
    ]
    data = {"per_image": per_image, "streams": streams, "errors": errors}
    return Result(rows, data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
