"""The wrist cameras' batch renderer on a GPU alone, for section 30 (bench/cameras_gpu.py).

Batches a second of MuJoCo Warp's batch renderer timed to completion on the device (BVH refit
+ render; also with the kinematics and camera poses the service recomputes), then of the
service's `BatchRenderer.render` (state in, pixels out to the host), plain and pipelined; and
the largest batch that fits, per resolution, each searched in a child process of its own (a
failed allocation must not poison the next try). Why apart from the section: this is the
renderer's ceiling, measured without the service; the section compares the stream with it.
"""

from __future__ import annotations

import contextlib
import gc
import json
import subprocess
import sys
import time
from typing import Any

from bench import common

SIZE = (64, 64)  # the wrist camera's size for the stream and the renderer alone
CAMERA = "wrist"


def _mjm_and_spec(width: int, height: int) -> tuple[Any, Any]:
    """The service's scene model and its wrist camera at width x height, RGB only."""
    from service.core.cameras.catalog import camera_specs
    from service.core.sim.robot import load_robot

    mjm = load_robot().mjm
    specs = camera_specs(mjm, f"{width}x{height}", "rgb")
    return mjm, next(s for s in specs if s.name == CAMERA)


def used_gib(device: str) -> float | None:
    """Memory in use on the device (every process), GiB; None where it cannot be read."""
    import warp as wp

    with contextlib.suppress(Exception):
        dev = wp.get_device(device)
        if dev.is_cuda:
            return (dev.total_memory - dev.free_memory) / 2**30
    return None


def _build(mjm: Any, spec: Any, n: int, device: str) -> tuple[Any, Any, Any]:
    """An mjwarp Model, Data of `n` worlds and render context, as the service's renderer builds."""
    import mujoco
    import mujoco_warp as mjw
    import warp as wp

    with wp.ScopedDevice(device):
        m = mjw.put_model(mjm)
        data = mujoco.MjData(mjm)
        mujoco.mj_kinematics(mjm, data)
        d = mjw.put_data(mjm, data, nworld=n, nconmax=1, njmax=1)
        outputs = {"render_rgb": [True], "render_depth": [False], "render_seg": [False]}
        rc = mjw.create_render_context(
            mjm, nworld=n, cam_res=[(spec.width, spec.height)], cam_active=[spec.id], **outputs
        )
    return m, d, rc


def _rate(t: common.Timing) -> dict[str, float]:
    return {"batches_per_s": 1 / t.per_call, "ms_per_batch": 1e3 * t.per_call}


def _device_rates(mjm: Any, spec: Any, n: int, device: str, seconds: float) -> dict[str, Any]:
    """Batches a second on the device alone: refit + render, and the service's whole picture."""
    import mujoco_warp as mjw
    import numpy as np
    import warp as wp

    t0 = time.perf_counter()
    m, d, rc = _build(mjm, spec, n, device)
    out: dict[str, Any] = {"build_s": time.perf_counter() - t0}

    def render() -> None:
        mjw.refit_bvh(m, d, rc)
        mjw.render(m, d, rc)

    def picture() -> None:
        mjw.kinematics(m, d)
        mjw.camlight(m, d)
        render()

    with wp.ScopedDevice(device):
        t0 = time.perf_counter()
        picture()
        wp.synchronize_device()
        out["first_draw_s"] = time.perf_counter() - t0  # compiles or loads the kernels
        for name, fn in (("render", render), ("picture", picture)):
            out[name] = _rate(common.time_calls(fn, seconds, 0, 3, 2, wp.synchronize_device))
        out["distinct_colours_world0"] = len(np.unique(rc.rgb_data.numpy()[0]))  # not blank
    out["gpu_used_gib"] = used_gib(device)
    return out


def _service_renderer_rate(mjm: Any, spec: Any, n: int, device: str, seconds: float) -> dict:
    """Batches a second of the service's BatchRenderer: state in, pixels out to the host, one
    picture at a time, and pipelined as the camera feed runs it (the next picture launched
    before this one's pixels are waited for); and whether the pipelined pictures are the plain
    path's, byte for byte (every world posed apart, so a mix-up of worlds or buffers shows)."""
    import numpy as np

    from service import heap
    from service.engines.camera_render import BatchRenderer

    heap.keep_large_blocks()  # as `armfleet serve` does
    renderer = BatchRenderer(mjm, [spec], n, device)
    rng = np.random.default_rng(7)
    qpos = np.tile(mjm.qpos0, (n, 1))
    qpos[:, :6] += rng.uniform(-0.3, 0.3, (n, 6))
    plain = renderer._render_all(qpos, spec).rgb
    first = renderer.launch(qpos, CAMERA)
    second = renderer.launch(qpos[::-1].copy(), CAMERA)  # into the other buffer, meanwhile
    same = bool(np.array_equal(first.result().rgb, plain))
    same = same and bool(np.array_equal(second.result().rgb, plain[::-1]))
    out = _rate(common.time_calls(lambda: renderer.render(qpos, CAMERA), seconds))
    reps, t0, pending = 0, time.perf_counter(), renderer.launch(qpos, CAMERA)
    while time.perf_counter() - t0 < seconds or reps < 3:
        following = renderer.launch(qpos, CAMERA)
        pending.result()
        pending, reps = following, reps + 1
    pending.result()
    took = (time.perf_counter() - t0) / (reps + 1)
    out["pipelined"] = {"batches_per_s": 1 / took, "ms_per_batch": 1e3 * took}
    out["pipelined_equals_plain"] = same
    return out


def renderer_alone(device: str, n: int, seconds: float) -> dict[str, Any]:
    """The renderer on the device alone, then the service's renderer, N worlds at SIZE."""
    import warp as wp

    mjm, spec = _mjm_and_spec(*SIZE)
    with contextlib.suppress(Exception):
        wp.set_mempool_release_threshold(device, 0)  # freed memory goes back to the device
    out: dict[str, Any] = {"worlds": n, "size": f"{spec.width}x{spec.height}"}
    out["gpu_used_before_gib"] = used_gib(device)
    out.update(_device_rates(mjm, spec, n, device, seconds))
    gc.collect()
    out["service"] = _service_renderer_rate(mjm, spec, n, device, seconds)
    gc.collect()
    wp.synchronize_device(device)
    return out


# -- the largest batch that fits (child processes) ----------------------------------------


def fit_child(device: str, width: int, height: int, start: int, cap: int) -> None:
    """The largest `start` x 2^k worlds (<= cap) whose render batch builds and draws, a JSON line
    per try. Memory grows with the worlds: after the first try the search jumps to the largest
    doubling the memory used predicts to fit, then halves back or doubles on from there: a plain
    doubling search's answer in fewer builds."""
    import mujoco_warp as mjw
    import warp as wp

    import service.engines.warp  # noqa: F401  (Warp's log level)

    mjm, spec = _mjm_and_spec(width, height)
    with contextlib.suppress(Exception):
        wp.set_mempool_release_threshold(device, 0)  # what is freed goes back: fair readings
    base = used_gib(device)

    def attempt(n: int) -> dict[str, Any]:
        print(json.dumps({"worlds": n}), flush=True)
        try:
            m, d, rc = _build(mjm, spec, n, device)
            with wp.ScopedDevice(device):
                t0 = time.perf_counter()
                mjw.refit_bvh(m, d, rc)
                mjw.render(m, d, rc)
                wp.synchronize_device()
            got = {"ok": True, "gpu_used_gib": used_gib(device)}
            got["draw_s"] = time.perf_counter() - t0
            del m, d, rc
        except Exception as exc:
            got = {"ok": False, "error": f"{type(exc).__name__}: {exc}"[:400]}
        gc.collect()
        with contextlib.suppress(Exception):
            wp.synchronize_device()
        print(json.dumps({"worlds": n, **got}), flush=True)
        return got

    first = attempt(start)
    if not first["ok"]:
        return
    n, bad, used = start, 2 * cap, first["gpu_used_gib"]
    if base is not None and used is not None and used > base:
        total, per_world = wp.get_device(device).total_memory / 2**30, (used - base) / start
        while n * 2 <= cap and base + per_world * n * 2 <= 0.95 * total:
            n *= 2
        while n > start and not attempt(n)["ok"]:
            bad, n = n, n // 2
    while n * 2 <= cap and n * 2 < bad and attempt(n * 2)["ok"]:
        n *= 2


def largest_fit(
    device: str, width: int, height: int, start: int, cap: int, timeout: float
) -> dict[str, Any]:
    """The largest worlds that fitted at width x height, and how the next doubling failed."""
    code = (
        "from bench.gpu_renderer import fit_child; "
        f"fit_child({device!r}, {width}, {height}, {start}, {cap})"
    )
    try:
        p = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout
        )
        text, err, rc = p.stdout, p.stderr, p.returncode
    except subprocess.TimeoutExpired as exc:
        text = exc.stdout.decode() if isinstance(exc.stdout, bytes) else exc.stdout or ""
        err, rc = f"stopped after {timeout:.0f} s", None
    lines = [json.loads(x) for x in text.splitlines() if x.startswith("{")]
    tries = [x for x in lines if "ok" in x]
    if lines and "ok" not in lines[-1]:  # the child died or ran out of time on this one
        tries.append({**lines[-1], "ok": False, "error": f"exit {rc}: {(err or '')[-300:]}"})
    best = max((x for x in tries if x["ok"]), key=lambda x: x["worlds"], default={})
    above = [x for x in tries if not x["ok"] and x["worlds"] > best.get("worlds", 0)]
    return {
        "size": f"{width}x{height}",
        "largest_worlds": best.get("worlds"),
        "gpu_used_gib": best.get("gpu_used_gib"),
        "megapixels": best["worlds"] * width * height / 1e6 if best else None,
        "next_failed": min(above, key=lambda x: x["worlds"]) if above else None,
        "capped": bool(best) and best["worlds"] * 2 > cap and not above,
        "tries": tries,
    }
