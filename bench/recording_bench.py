"""Section 16: what recording, replay and snapshots cost.

* Recording overhead at 64 worlds: the same service without and with `--record` of every world
  at every tick (`--record-worlds 0-63 --record-rate 60`, the heaviest setting), measured as the
  real-time factor in realtime mode and as ticks/s in fast mode, one window each.
* Replay: `service.persistence.replay.replay` of that recording (one WorldBatch, paused loop
  stepped tick by tick through the control layer, every recorded state compared): ticks/s and
  world-steps/s.
* Snapshots at 1024 worlds: file size, and the wall time of `POST /v1/snapshots` (state taken
  between ticks, written and fsynced) and of `POST /v1/snapshots/{name}/restore` (file read and
  checked, applied between ticks), median of 5 each.

Standalone: ``python -m bench.recording_bench [--quick]`` or ``armfleet bench --section 16``.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from bench import common
from bench.registry import Context, Result, section

RECORD_WORLDS = 64
SNAPSHOT_WORLDS = 1024


def _rates(srv: common.Served, window: float) -> dict[str, float]:
    """RTF in realtime mode, then ticks/s in fast mode, one window each (after a warm-up)."""
    http = httpx.Client(base_url=srv.url, timeout=60)
    out: dict[str, float] = {}
    for mode in ("realtime", "fast"):
        http.post("/v1/sim/mode", json={"mode": mode}).raise_for_status()
        time.sleep(min(2.0, window / 3))
        a = srv.get_info()
        time.sleep(window)
        b = srv.get_info()
        ticks = b[1]["tick"] - a[1]["tick"]
        out[f"{mode}_rtf"] = common.rtf_between(a, b)
        out[f"{mode}_ticks_per_s"] = ticks / (b[0] - a[0])
    http.post("/v1/sim/mode", json={"mode": "paused"}).raise_for_status()
    return out


def _recording(ctx: Context, tmp: Path, window: float) -> tuple[dict[str, Any], Path]:
    path = tmp / "run.mcap"
    runs: dict[str, Any] = {}
    with ctx.serve(RECORD_WORLDS, "realtime", env={"ARMFLEET_DATA_DIR": str(tmp)}) as srv:
        runs["without"] = _rates(srv, window)
    env = {
        "ARMFLEET_DATA_DIR": str(tmp),
        "ARMFLEET_RECORD": str(path),
        "ARMFLEET_RECORD_WORLDS": f"0-{RECORD_WORLDS - 1}",
        "ARMFLEET_RECORD_RATE": "60",
    }
    with ctx.serve(RECORD_WORLDS, "realtime", env=env) as srv:
        runs["with"] = _rates(srv, window)
        status = httpx.get(f"{srv.url}/v1/recordings/current", timeout=30).json()
    runs["recording_status"] = status
    runs["file_bytes"] = path.stat().st_size if path.exists() else None
    return runs, path


def _snapshots(ctx: Context, tmp: Path, repeats: int) -> dict[str, Any]:
    env = {"ARMFLEET_DATA_DIR": str(tmp), "ARMFLEET_SAVE_ON_EXIT": "false"}
    with ctx.serve(SNAPSHOT_WORLDS, "realtime", env=env) as srv:
        http = httpx.Client(base_url=srv.url, timeout=120)
        saves, restores = [], []
        size = 0
        for i in range(repeats):
            t0 = time.perf_counter()
            r = http.post("/v1/snapshots", json={"name": f"b{i}"})
            saves.append(time.perf_counter() - t0)
            r.raise_for_status()
            size = r.json()["size_bytes"]
        for i in range(repeats):
            t0 = time.perf_counter()
            http.post(f"/v1/snapshots/b{i}/restore").raise_for_status()
            restores.append(time.perf_counter() - t0)
        shards = srv.info.get("shards")
    return {
        "nworld": SNAPSHOT_WORLDS,
        "shards": shards,
        "size_bytes": size,
        "save_s": saves,
        "restore_s": restores,
        "save_median_s": statistics.median(saves),
        "restore_median_s": statistics.median(restores),
    }


@section(16, "recording")
def recording(ctx: Context) -> Result:
    """Recording overhead at 64 worlds, replay speed, snapshots at 1024"""
    from service.persistence.replay import replay

    window = ctx.pick(10.0, 4.0)
    data: dict[str, Any] = {"errors": {}}
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="armfleet-bench-rec-") as tmp_s:
        tmp = Path(tmp_s)
        try:
            runs, path = _recording(ctx, tmp, window)
            data["record"] = runs
            for key in ("without", "with"):
                r = runs[key]
                rows.append(
                    {
                        "what": f"{RECORD_WORLDS} worlds, {key} --record (all worlds, every tick)",
                        "realtime RTF": round(r["realtime_rtf"], 3),
                        "fast ticks/s": round(r["fast_ticks_per_s"], 1),
                    }
                )
            ctx.say(f"  recording: {runs}")
            report = replay(path)
            data["replay"] = {
                "ticks": report.ticks,
                "wall_s": report.wall_s,
                "ticks_per_s": report.ticks_per_s,
                "world_steps_per_s": report.ticks_per_s * RECORD_WORLDS * _substeps(ctx),
                "states_compared": report.states_compared,
                "identical": report.divergence is None,
                "divergence": None if report.divergence is None else str(report.divergence),
            }
            rows.append(
                {
                    "what": f"replay of that recording ({report.ticks} ticks, one WorldBatch)",
                    "fast ticks/s": round(report.ticks_per_s, 1),
                    "identical": report.divergence is None,
                }
            )
        except Exception as exc:
            data["errors"]["record/replay"] = f"{type(exc).__name__}: {exc}"
        try:
            snap = _snapshots(ctx, tmp, ctx.pick(5, 2))
            data["snapshots"] = snap
            rows.append(
                {
                    "what": f"snapshot of {SNAPSHOT_WORLDS} worlds ({snap['shards']} shards)",
                    "size MB": round(snap["size_bytes"] / 1e6, 2),
                    "save ms": round(snap["save_median_s"] * 1e3, 1),
                    "restore ms": round(snap["restore_median_s"] * 1e3, 1),
                }
            )
        except Exception as exc:
            data["errors"]["snapshots"] = f"{type(exc).__name__}: {exc}"
    notes = [
        "RTF: simulated s per wall s in realtime mode; fast: ticks/s with nobody streaming.",
        "save/restore: wall time of the HTTP request, median; includes fsync and the full check.",
    ]
    return Result(rows, data, notes)


def _substeps(ctx: Context) -> int:
    from service.core.sim.physics import DEFAULT_PHYSICS_DT, tick_timing

    return tick_timing(60.0, DEFAULT_PHYSICS_DT)[0]


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
