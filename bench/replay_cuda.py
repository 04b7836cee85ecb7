"""CUDA determinism and replay: do two runs of the same commands give the same bits, and if not,
how far apart do they drift over 600+ ticks with contacts? What does deterministic stepping cost?

Three stepping modes, each in a process of its own (Warp's deterministic switch is per process):

* default: MuJoCo Warp as it comes (`opt.deterministic = 0`);
* atomics: MuJoCo Warp's own switch only (`opt.deterministic = ATOMICS`: its reductions run in
  Warp's RUN_TO_RUN mode; contact and constraint-row order stay as they come);
* deterministic: Warp's process-wide RUN_TO_RUN mode (bench/warp_modes.py: counter slots, i.e.
  contact and row order, deterministic too) plus every MuJoCo Warp bit.

In each: a probe (the same start state stepped twice through the same grasp commands, every
world's seven joints compared bit for bit at every tick, the largest deviation per 60-tick range),
the stepping rate at 4096 worlds (graph captured), and for default a recording made through the
loop, control layer and recorder the service uses, replayed by `service.replay.replay` (`armfleet
replay --device cuda`) on the same GPU. The grasp: every world closes its gripper on its cube,
lifts it, puts it down and opens, in a 444-tick cycle started at a different phase per world, so
pads, cube and table are in contact at every tick in some worlds.

``python -m bench.replay_cuda --out replay_cuda.json`` on the GPU machine (Warp, MuJoCo and the
service's recording dependencies only; no HTTP server).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

# Arm targets [rad] from tests/test_model.py's IK (pinch 2 cm above the cube centre, and 12 cm
# above it, flange orientation as at home), rounded; finger 0 open, 0.7 closed on the cube.
HOME = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
GRASP = np.array([-0.00029, -1.5207, 1.84659, -1.8959, -1.57, -0.00029])
LIFT = np.array([-0.00029, -1.55976, 1.70676, -1.717, -1.57, -0.00029])
# (arm, finger, ticks to get there from the previous key)
CYCLE = [
    (GRASP, 0.0, 72),
    (GRASP, 0.7, 48),
    (LIFT, 0.7, 72),
    (LIFT, 0.7, 60),
    (GRASP, 0.7, 72),
    (GRASP, 0.0, 48),
    (HOME, 0.0, 72),
]
PERIOD = sum(n for *_, n in CYCLE)
TICKS = 660
SPAN = 60
MODES = ("default", "deterministic", "atomics")


def cycle_targets() -> np.ndarray:
    """(PERIOD, 7) targets of one grasp cycle, moving linearly between the keys."""
    rows, arm, finger = [], HOME, 0.0
    for to_arm, to_finger, n in CYCLE:
        for k in range(1, n + 1):
            s = k / n
            rows.append(np.append(arm + s * (to_arm - arm), finger + s * (to_finger - finger)))
        arm, finger = to_arm, to_finger
    return np.array(rows)


def plan(ticks: int, nworld: int) -> np.ndarray:
    """(ticks, nworld, 7): world w runs the cycle started (37 w mod PERIOD) ticks in."""
    cyc = cycle_targets()
    phase = (np.arange(nworld) * 37) % PERIOD
    return cyc[(np.arange(ticks)[:, None] + phase[None, :]) % PERIOD]


DEVICE = os.environ.get("ARMFLEET_BENCH_DEVICE", "cuda")  # cpu: a smoke test of this script


PREBUILT: dict[str, Any] = {}  # what bench.warp_modes.prebuild did in this process


def make_batch(mode: str, nworld: int) -> Any:
    import mujoco_warp as mjw

    from bench.warp_modes import enable, prebuild
    from service.engines.warp import WorldBatch

    if mode == "deterministic":
        enable()
    if not PREBUILT:
        walk = lambda: WorldBatch(nworld, device=DEVICE, capture=False)  # noqa: E731
        PREBUILT.update(prebuild(DEVICE, walk))
    if mode == "default":
        return WorldBatch(nworld, device=DEVICE)
    bits = mjw.DeterminismType.ATOMICS if mode == "atomics" else mjw.DeterminismType.ALL
    batch = WorldBatch(nworld, device=DEVICE, capture=False)
    batch._m.opt.deterministic = int(bits)
    batch._run_tick_ops()  # compile the RUN_TO_RUN variants before capturing them
    batch.reset(np.arange(nworld))
    batch._capture()
    return batch


def run_once(batch: Any, start: Any, targets: np.ndarray) -> tuple[np.ndarray, int]:
    """States (ticks, nworld, 21) float32 stepping `targets` from `start`; peak constraint rows."""
    batch.set_state(start)
    worlds = np.arange(batch.nworld)
    out = np.empty((len(targets), batch.nworld, 21), dtype=np.float32)
    rows = 0
    for t, tgt in enumerate(targets):
        batch.apply_targets(worlds, tgt)
        batch.step(1)
        s = batch.snapshot()
        out[t] = np.concatenate([s.position, s.velocity, s.effort], axis=1)
        if t % 10 == 0:
            rows = max(rows, batch.capacity_usage()[1])
    return out, rows


def compare_runs(a: np.ndarray, b: np.ndarray) -> dict[str, Any]:
    """Bitwise and numeric comparison of two runs, per tick range."""
    same = a.view(np.uint32) == b.view(np.uint32)
    per_tick = same.all(axis=(1, 2))
    diff = np.abs(a.astype(np.float64) - b.astype(np.float64))
    ranges = []
    for lo in range(0, len(a), SPAN):
        d = diff[lo : lo + SPAN]
        ranges.append(
            {
                "ticks": f"{lo + 1}-{min(lo + SPAN, len(a))}",
                "worlds_differing": int((~same[lo : lo + SPAN].all(axis=(0, 2))).sum()),
                "max_abs_position": float(d[..., :7].max()),
                "max_abs_velocity": float(d[..., 7:14].max()),
                "max_abs_effort": float(d[..., 14:].max()),
            }
        )
    first = np.flatnonzero(~per_tick)
    return {
        "bit_identical": bool(per_tick.all()),
        "first_differing_tick": int(first[0]) + 1 if first.size else None,
        "ticks_differing": int((~per_tick).sum()),
        "worlds_differing_at_end": int((~same[-1].all(axis=1)).sum()),
        "ranges": ranges,
    }


def rate(batch: Any, seconds: float = 3.0) -> dict[str, float]:
    batch.step(10)
    t0, k0 = time.perf_counter(), batch.tick
    while time.perf_counter() - t0 < seconds:
        batch.step(10)
    dt = time.perf_counter() - t0
    ticks = batch.tick - k0
    return {
        "nworld": batch.nworld,
        "ticks_per_s": round(ticks / dt, 1),
        "world_steps_per_s": round(ticks * batch.substeps * batch.nworld / dt),
    }


def record_and_replay(mode: str, nworld: int, path: Path) -> dict[str, Any]:
    """Record `nworld` worlds driven through the control layer, replay on the same GPU."""
    from service.core.commands.control import Control
    from service.core.sim.loop import SimLoop
    from service.core.sim.types import Mode
    from service.persistence.recorder import Recorder
    from service.persistence.replay import replay

    batch = make_batch(mode, nworld)
    loop = SimLoop(batch, Mode.PAUSED)
    control = Control(loop)
    loop.start()

    class _Runtime:
        def __init__(self) -> None:
            self.loop, self.control = loop, control

    shown = min(16, nworld)
    rec = Recorder(path, f"0-{shown - 1}", rate=batch.control_hz, block=True)
    rec.start(_Runtime())
    targets = plan(TICKS, nworld)
    for t in range(TICKS):
        control.set_many(list(range(nworld)), targets[t], "http")
        loop.step(1).result()
    rec.stop()
    loop.stop()
    del batch
    t0 = time.perf_counter()
    report = replay(path, device=DEVICE)
    return {
        "nworld": nworld,
        "recorded_worlds": shown,
        "ticks": report.ticks,
        "states_compared": report.states_compared,
        "replay_s": round(time.perf_counter() - t0, 1),
        "compared": "bit for bit" if report.tolerance is None else str(report.tolerance),
        "divergence": None if report.divergence is None else str(report.divergence),
        "largest": report.largest,
        "deviations": [r.as_dict() for r in report.deviations],
    }


def one_mode(mode: str, out: Path, sizes: tuple[int, int, int]) -> None:
    """Everything for one mode, in this process; results saved after each step."""
    result: dict[str, Any] = {"mode": mode}

    def save() -> None:
        out.write_text(json.dumps(result, indent=1))

    t0 = time.perf_counter()
    probe, fast, recorded = sizes
    batch = make_batch(mode, probe)
    result["build_s"] = round(time.perf_counter() - t0, 1)  # prebuild included
    result["prebuild"] = dict(PREBUILT)
    result["captured"] = batch.captured
    save()
    start = batch.get_state()
    targets = plan(TICKS, batch.nworld)
    a, rows = run_once(batch, start, targets)
    b, _ = run_once(batch, start, targets)
    result["probe"] = {"nworld": batch.nworld, "ticks": TICKS, "peak_constraint_rows": rows}
    result["probe"].update(compare_runs(a, b))
    save()
    del batch, a, b
    result["rate"] = rate(make_batch(mode, fast))
    save()
    if mode == "default":  # replay runs the service's (default) mode
        with tempfile.TemporaryDirectory() as tmp:
            result["replay"] = record_and_replay(mode, recorded, Path(tmp) / "run.mcap")
        save()
    if mode == "deterministic":
        from bench.warp_modes import fallbacks

        result["fallback_modules"] = sorted(set(fallbacks))
        save()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="replay_cuda.json")
    ap.add_argument("--mode", choices=MODES, default=None, help="one mode, in this process")
    ap.add_argument("--budget", type=float, default=540.0, help="seconds for all modes")
    ap.add_argument("--sizes", default="1024,4096,256", help="worlds: probe, rate, recording")
    ap.add_argument("--modes", default=",".join(MODES))
    a = ap.parse_args(argv)
    out = Path(a.out)
    sizes = tuple(int(x) for x in a.sizes.split(","))
    if a.mode:
        one_mode(a.mode, out, sizes)  # type: ignore[arg-type]
        return 0
    import warp as wp

    gpus = wp.get_cuda_devices()
    payload: dict[str, Any] = {
        "gpu": gpus[0].name if gpus else None,
        "versions": {"warp": wp.config.version},
        "sizes": {"probe": sizes[0], "rate": sizes[1], "recording": sizes[2]},
        "modes": {},
    }
    deadline = time.monotonic() + a.budget
    for mode in a.modes.split(","):
        part = out.with_suffix(f".{mode}.json")
        t0 = time.perf_counter()
        cmd = [sys.executable, "-m", "bench.replay_cuda", "--mode", mode, "--out", str(part)]
        cmd += ["--sizes", a.sizes]
        left = deadline - time.monotonic()
        if left < 30:
            payload["modes"][mode] = {"status": "not run: out of time"}
            continue
        log = out.with_suffix(f".{mode}.log")
        try:
            with open(log, "w") as fh:  # streamed: a mode that runs out of time still shows why
                proc = subprocess.run(cmd, timeout=left, stdout=fh, stderr=subprocess.STDOUT)
            status = f"exit {proc.returncode}"
        except subprocess.TimeoutExpired:
            status = "timed out"
        lines = [x for x in log.read_text(errors="replace").splitlines() if "iterations" not in x]
        tail = "\n".join(lines)[-3000:]
        res = json.loads(part.read_text()) if part.exists() else {}
        res.update({"status": status, "wall_s": round(time.perf_counter() - t0, 1)})
        if status != "exit 0":
            res["log_tail"] = tail
        payload["modes"][mode] = res
        out.write_text(json.dumps(payload, indent=1))
        print(mode, status, json.dumps(res)[:2000], flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
