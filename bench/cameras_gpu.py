"""Section 30: cameras on a GPU: every world's wrist camera streamed at 30 Hz, beside the renderer.

On the CUDA device, in one run: (1) the renderer alone: MuJoCo Warp's batch renderer, N = 16,384
worlds' wrist camera at 64x64 RGB, timed to completion on the device (BVH refit + render; also with
the kinematics and camera poses the service recomputes), then the service's `BatchRenderer.render`
(state in, pixels out to the host); (2) `armfleet serve` with N worlds, the wrist camera at 64x64
RGB, `--camera-batch N`, and clients of `/v1/ws/cameras?worlds=..&rate=30&format=raw` (one client
asking every world, then 8 client processes asking an eighth each; no compression), in realtime
then fast mode: ticks/s and real-time factor with nobody looking, then while the stream runs,
pictures of every world delivered a second and their ratio to min(30, the renderer alone's
batches/s); on a machine of two GPUs or more, also the 8-client streams with the cameras on
the second GPU (`--camera-device cuda:1`; the engine steps in a process of its own on the
first); (3) the largest batch that fits: per resolution, the worlds doubled from N
until building or drawing the render batch fails (a child process per resolution).

Run it: ``armfleet bench --section 30 --device cuda`` (``--quick``: 1,024 worlds, shorter).
The renderer alone and the largest fit are measured in bench/gpu_renderer.py; the stream's
client processes are bench/camera_readers.py; this module serves, streams and compares.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import subprocess
import time
from pathlib import Path
from typing import Any

import httpx

from bench import common
from bench.camera_readers import Readers, client_name
from bench.gpu_renderer import CAMERA, SIZE, largest_fit, renderer_alone, used_gib
from bench.registry import Context, Result, section

RATE = 30.0  # messages a second asked of the stream
FIT_SIZES = ((64, 64), (128, 128), (256, 256))
FIT_MAX_WORLDS = 1 << 22  # the doubling stops here even when memory is left
STREAMS = (("realtime", 1), ("realtime", 8), ("fast", 8))  # (mode, client processes)
# On a machine of two GPUs or more, also these, with the cameras on the second GPU (the engine
# then steps in a worker process of its own on the first: `EngineSettings.apart`)
APART_STREAMS = (("realtime", 8, "cuda:1"), ("fast", 8, "cuda:1"))
# ARMFLEET_BENCH_CLIENT=websockets: the stream clients use the websockets sync client (else aiohttp)
# ARMFLEET_BENCH_FITS=0: take the largest fits from the last run's file instead of searching
# ARMFLEET_BENCH_STREAMS=realtime:8,fast:8: only these streams (mode:clients), to save device time;
#   realtime:8@cuda:1 serves the cameras on a GPU of their own (--camera-device cuda:1)
# ARMFLEET_BENCH_PYSPY=/path/to/py-spy: while each stream runs, record which of the server's
#   threads hold the interpreter (py-spy --gil, collapsed stacks) into the --out folder;
#   with ARMFLEET_BENCH_PYSPY_WALL=1, where every thread is, waiting or not (py-spy --idle)
FITS_BEFORE = Path(__file__).parent / "results" / "cameras_gpu_cuda.json"


def _cuda_count() -> int:
    """CUDA devices on this machine (0 where warp finds none)."""
    import warp as wp

    with contextlib.suppress(Exception):
        return int(wp.get_cuda_device_count())
    return 0


# -- the service, streaming ------------------------------------------------------------------


def _metrics(url: str) -> dict[str, float]:
    lines = httpx.get(f"{url}/metrics", timeout=60).text.splitlines()
    return {x.split()[0]: float(x.split()[1]) for x in lines if x.startswith("armfleet_camera")}


def _window(
    srv: common.Served, seconds: float, readers: Readers | None, srv_device: str
) -> dict[str, Any]:
    """Ticks/s, RTF, frames/s (pictures of every world), messages/s, the cameras' metrics."""

    def seen() -> tuple[float, int]:
        return (readers.frames(), readers.messages()) if readers else (0.0, 0)

    m0, (f0, n0), a = _metrics(srv.url), seen(), srv.get_info()
    time.sleep(seconds)
    m1, (f1, n1), b = _metrics(srv.url), seen(), srv.get_info()
    wall = b[0] - a[0]
    d = {k.removeprefix("armfleet_camera_"): m1[k] - m0.get(k, 0.0) for k in m1}
    renders = d.get("renders_total") or math.nan
    return {
        "wall_s": wall,
        "ticks_per_s": (b[1]["tick"] - a[1]["tick"]) / wall,
        "rtf": common.rtf_between(a, b),
        "frames_per_s": (f1 - f0) / wall,
        "messages_per_s": (n1 - n0) / wall,
        "renders_per_s": d.get("renders_total", 0.0) / wall,
        "render_ms": 1e3 * d.get("render_seconds_total", 0.0) / renders,
        "state_ms": 1e3 * d.get("state_seconds_total", 0.0) / renders,
        "gpu_used_gib": used_gib(srv_device),
    }


def _ready(url: str) -> float:
    """Wait until the service's cameras are warm; the seconds their warm-up took."""
    for _ in range(1800):
        if (got := httpx.get(f"{url}/v1/cameras", timeout=60).json())["ready"]:
            return float(got.get("warm_s") or 0.0)
        time.sleep(0.5)
    raise TimeoutError("cameras not ready in 900 s")


def stream(
    ctx: Context, n: int, mode: str, clients: int, window: float, camera_device: str = ""
) -> dict[str, Any]:
    """`armfleet serve --mode MODE`, N worlds: a window idle, then one while every world streams
    to `clients` readers, each asking its share of the worlds; `camera_device`: the cameras on
    a device of their own (--camera-device), else on the engine's."""
    w, h = SIZE
    env = {f"ARMFLEET_{k}": v for k, v in (("CAMERA_SIZE", f"{w}x{h}"), ("CAMERA_BATCH", str(n)))}
    env |= {"ARMFLEET_CAMERA_OUTPUTS": "rgb", "ARMFLEET_CAMERAS": "overview=off"}
    env |= {"ARMFLEET_CAMERA_DEVICE": camera_device} if camera_device else {}
    out: dict[str, Any] = {"mode": mode, "worlds": n, "clients": clients}
    out["camera_device"] = camera_device or None
    with ctx.serve(n, mode, env) as srv:
        out["ready_s"], out["cameras_warm_s"] = srv.ready_s, _ready(srv.url)
        time.sleep(2.0)
        out["idle"] = _window(srv, window, None, ctx.device)
        readers = Readers(srv.ws_url, n, clients, CAMERA, RATE)
        try:
            deadline = time.monotonic() + 120
            while readers.frames() < 2 and time.monotonic() < deadline:
                time.sleep(0.1)
            time.sleep(1.0)
            spy = _profile(ctx, srv, f"gil_{mode}_{clients}.txt", window)
            out["streaming"] = _window(srv, window, readers, ctx.device)
            if spy is not None:
                out["profile"] = _profiled(spy)
        finally:
            out["client"] = readers.close()
    out["whole_messages"] = out["client"]["whole_messages"] and out["client"]["image_bytes"] == [
        w * h * 3
    ]
    return out


def _profile(ctx: Context, srv: common.Served, name: str, seconds: float) -> Any:
    """py-spy recording the server's interpreter holders for `seconds` (ARMFLEET_BENCH_PYSPY)."""
    spy = os.environ.get("ARMFLEET_BENCH_PYSPY")
    if not spy:
        return None
    path = Path(ctx.out_dir) / name
    how = "--idle" if os.environ.get("ARMFLEET_BENCH_PYSPY_WALL") == "1" else "--gil"
    if how == "--idle":
        path = path.with_name(path.name.replace("gil_", "wall_"))
    cmd = [spy, "record", how, "--threads", "--rate", "200", "--format", "raw"]
    cmd += ["--duration", f"{seconds:.0f}", "--pid", str(srv.server.process.pid), "-o", str(path)]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True), path


def _profiled(spy: Any) -> dict[str, Any]:
    """The recording's top frames by samples (where the interpreter went while streaming)."""
    proc, path = spy
    try:
        log = proc.communicate(timeout=60)[0][-500:]
    except subprocess.TimeoutExpired:
        proc.kill()
        log = "py-spy did not finish"
    leaves: dict[str, int] = {}
    threads: dict[str, int] = {}
    total = 0
    with contextlib.suppress(OSError):
        for line in Path(path).read_text().splitlines():
            stack, _, count = line.rpartition(" ")
            n = int(count)
            total += n
            frames = stack.split(";")
            threads[frames[0]] = threads.get(frames[0], 0) + n
            for frame in frames[-3:]:  # the innermost frames: what held the interpreter
                leaves[frame] = leaves.get(frame, 0) + n
    top = sorted(leaves.items(), key=lambda kv: -kv[1])[:25]
    return {"file": str(path), "samples": total, "threads": threads, "top": top, "log": log}


# -- the section -----------------------------------------------------------------------------


def _rooms(alone: dict, streams: list[dict]) -> None:
    """Each stream's `room`: the renderer alone's batches/s times the share of the device its
    ticks leave, 1 - (ticks/s while streaming) / (ticks/s in fast mode with nobody looking,
    this run); and the stream's ratio to min(30, room). A model: a tick is taken to cost the
    device the same beside pictures as alone, and the two are taken not to overlap."""
    fast = [s["idle"]["ticks_per_s"] for s in streams if s["mode"] == "fast"]
    if not alone or not fast:
        return
    for s in streams:
        if s.get("camera_device"):  # a device of their own: nothing shares it
            continue
        left = max(0.0, 1.0 - s["streaming"]["ticks_per_s"] / max(fast))
        s["room"] = alone["render"]["batches_per_s"] * left
        best = min(RATE, s["room"])
        s["ratio_to_room"] = s["streaming"]["frames_per_s"] / best if best > 0 else None


def _rows(alone: dict, streams: list[dict], fits: list[dict], n: int) -> list[dict[str, Any]]:
    shape = f"{n:,} worlds x {SIZE[0]}x{SIZE[1]} RGB"
    got: list[tuple[str, Any]] = []
    if alone:
        per_s = {k: alone[k]["batches_per_s"] for k in ("render", "picture", "service")}
        got += [
            (f"renderer alone: batches/s ({shape}; refit + render)", per_s["render"]),
            ("renderer alone: images/s", per_s["render"] * n),
            ("renderer + kinematics, camera poses: batches/s", per_s["picture"]),
            ("service's renderer (state in, pixels out): batches/s", per_s["service"]),
            (
                "service's renderer, pipelined: batches/s",
                alone["service"].get("pipelined", {}).get("batches_per_s"),
            ),
            (
                "pipelined pictures equal the plain path's",
                alone["service"].get("pipelined_equals_plain"),
            ),
        ]
    for s in streams:
        st, how = s["streaming"], f"{s['mode']}, {s['clients']} client(s)"
        if s.get("camera_device"):
            how += f", cameras on {s['camera_device']}"
        got += [
            (f"{how}: every world's picture, per second, asked at 30", st["frames_per_s"]),
            (f"{how}: stream ratio to the renderer alone, min(30, batches/s)", s.get("ratio")),
            (f"{how}: ticks/s, nobody looking", s["idle"]["ticks_per_s"]),
            (f"{how}: ticks/s, while streaming", st["ticks_per_s"]),
            (f"{how}: ms per render in the service (draw, pixels to host)", st["render_ms"]),
        ]  # fmt: skip
        if s.get("room") is not None:
            got += [
                (f"{how}: batches/s the device has room for beside these ticks", s["room"]),
                (f"{how}: stream ratio to that room, min(30, room)", s["ratio_to_room"]),
            ]
    for f in fits:
        capped = " (search capped)" if f["capped"] else ""
        got.append((f"largest batch that fits at {f['size']}: worlds{capped}", f["largest_worlds"]))
    return [{"measure": k, "value": v} for k, v in got]


@section(30, "cameras_gpu", devices=("cuda",), default_on=("cuda",))
def cameras_gpu(ctx: Context) -> Result:
    """Cameras on the GPU: 16,384 wrist cameras streamed at 30 Hz vs the renderer alone"""
    n = ctx.sizes((16384,), quick=(1024,))[0]
    seconds, window = ctx.pick((5.0, 10.0), (2.0, 3.0))
    errors: dict[str, str] = {}
    alone: dict[str, Any] = {}
    try:
        alone = renderer_alone(ctx.device, n, seconds)
        ctx.say(f"  renderer alone: {alone['render']['batches_per_s']:.1f} batches/s of {n}")
    except Exception as exc:
        errors["renderer_alone"] = f"{type(exc).__name__}: {exc}"
        ctx.say(f"  renderer alone FAILED: {errors['renderer_alone']}")
    best = min(RATE, alone["render"]["batches_per_s"]) if alone else None
    streams = []
    chosen = os.environ.get("ARMFLEET_BENCH_STREAMS")
    streams_asked: tuple[tuple[str, Any, str], ...] = tuple((m, c, "") for m, c in STREAMS)
    if _cuda_count() >= 2:
        streams_asked += APART_STREAMS
    if chosen:
        pairs = (x.partition(":") for x in chosen.split(","))
        streams_asked = tuple((m, *c.partition("@")[::2]) for m, _, c in pairs)
    for mode, clients, camera_device in streams_asked:
        try:
            s = stream(ctx, n, mode, int(clients), window, camera_device)
            s["ratio"] = s["streaming"]["frames_per_s"] / best if best else None
            streams.append(s)
            idle, st = s["idle"]["ticks_per_s"], s["streaming"]["ticks_per_s"]
            at = f" (cameras on {camera_device})" if camera_device else ""
            got = s["streaming"]["frames_per_s"]
            ctx.say(f"  {mode}, {clients} client(s){at}: {got:.2f} frames/s")
            ctx.say(f"    ticks/s {idle:.1f} nobody looking, {st:.1f} streaming")
        except Exception as exc:
            errors[f"stream {mode} {clients}"] = f"{type(exc).__name__}: {exc}"
            ctx.say(f"  {mode} stream FAILED: {errors[f'stream {mode} {clients}']}")
    _rooms(alone, streams)
    fits, fits_from, fits_card = [], None, None
    if os.environ.get("ARMFLEET_BENCH_FITS", "1") == "0" and FITS_BEFORE.exists():
        before = json.loads(FITS_BEFORE.read_text())  # the renderer alone did not change
        fits, fits_from = before["fits"], before.get("fits_from") or before["started"]
        fits_card = before.get("fits_card") or before.get("card")
    for w, h in ctx.pick(FIT_SIZES, FIT_SIZES[:1]) if fits_from is None else ():
        f = largest_fit(ctx.device, w, h, n, ctx.pick(FIT_MAX_WORLDS, 2 * n), ctx.pick(150, 90))
        fits.append(f)
        ctx.say(f"  fits at {w}x{h}: {f['largest_worlds']} worlds ({f['gpu_used_gib']} GiB)")
    gpu = common.gpu_name(ctx.device) or ""
    card = "H200" if "H200" in gpu else "H100" if "H100" in gpu else gpu or "none"
    notes = [
        f"card: {card} ({gpu or 'no GPU'}); WebSocket clients ({client_name()}) on the same "
        "machine, each a process asking an equal share of the worlds, raw pixels, no "
        "compression; ratio: pictures of every world delivered a second over min(30, the "
        "renderer's batches/s); room: the renderer alone's batches/s x the share of the device "
        "the ticks leave (1 - ticks/s streaming / ticks/s in fast mode with nobody looking; a "
        "model, no overlap); largest fit: the renderer alone (the service draws at most 2^26 "
        "pixels a render)"
    ]
    if fits_from:
        notes.append(f"largest fit: carried from the run started {fits_from} on {fits_card}")
    data = dict(card=card, gpu=gpu, worlds=n, size=f"{SIZE[0]}x{SIZE[1]}", rate=RATE)
    data["client"] = client_name()
    data.update(renderer_alone=alone, streams=streams, fits=fits, errors=errors)
    data["fits_from"], data["fits_card"] = fits_from, fits_card or card
    return Result(_rows(alone, streams, fits, n), data, notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
