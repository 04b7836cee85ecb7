"""The README's performance tables and headline, regenerated from bench/results/*.json.

Each table sits in README.md between ``<!-- bench:NAME -->`` and ``<!-- /bench:NAME -->``;
``python -m bench.readme_tables`` rewrites what is between them from the results files, so the
figures in the README are always those of a recorded run. ``--check`` only says whether the
README is up to date (exit 1 if not).
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench import common, figures

README = Path(__file__).resolve().parents[1] / "README.md"

GPU_HEAD = (
    "worlds",
    "engine",
    "raw MJWarp captured",
    "engine / raw",
    "served, binary (frames/s)",
    "binary / engine",
    "served, JSON (frames/s)",
    "JSON / engine",
)

PROFILE_HEAD = (
    "worlds",
    "path / frames",
    "engine ms",
    "served ms",
    "served / engine",
    "frames/s",
    "snapshot s/s",
    "pack s/s",
    "serialise s/s",
)

BASELINE_HEAD = (
    "worlds",
    "variant",
    "ms/tick (settled)",
    "ms/tick by quarter from home",
    "variant / engine",
)

CAPACITY_HEAD = (
    "engine",
    "frames",
    "share of the limit held",
    "held at RTF ≥ 0.99 (worlds)",
    "× the limit beside it",
    "× the best limit of the run",
    "engine share of the wall",
    "next tried: worlds, RTF, × limit beside",
)


def _rtf(x: float) -> str:
    """A real-time factor to 3 decimals, rounded down: 0.98997 fails the 0.99 goal and shows
    0.989, not 0.990."""
    return f"{math.floor(x * 1000) / 1000:.3f}"


def _load(name: str) -> dict[str, Any]:
    return common.read_json(name, common.RESULTS_DIR) or {}


def _machine(payload: dict[str, Any]) -> str:
    m = payload.get("machine", {})
    return f"{m.get('gpu') or m.get('cpu_model')}, {payload.get('started', '?')}"


def gpu() -> str:
    """Sections 1, 7 and 2 on CUDA: engine, raw graph, the service with binary and JSON frames."""
    tp, binary, js = (
        _load(f"{n}_cuda.json") for n in ("throughput", "service_fast_binary", "service_fast")
    )
    rows = []
    for n, entry in tp.get("results", {}).items():
        eng = entry["engines"].get("engine", {}).get("world_steps_per_s")
        raw = entry["engines"].get("warp_captured", {}).get("world_steps_per_s")
        b = binary.get("results", {}).get(n, {})
        j = js.get("results", {}).get(n, {})
        rows.append(
            [
                f"{int(n):,}",
                common.fmt_rate(eng),
                common.fmt_rate(raw),
                common.fmt_ratio(eng / raw if eng and raw else None),
                f"{common.fmt_rate(b.get('world_steps_per_s'))} ({b.get('frames_per_s', 0):.1f}/s)",
                common.fmt_ratio(b.get("ratio_to_engine")),
                f"{common.fmt_rate(j.get('world_steps_per_s'))} ({j.get('frames_per_s', 0):.1f}/s)",
                common.fmt_ratio(j.get("ratio_to_engine")),
            ]
        )
    head = list(GPU_HEAD)
    note = f"\n\n({_machine(tp)}; world-steps/s, 30 Hz asked)"
    tried = _load("warp_baseline_cuda.json").get("largest") or []
    fits = [t for t in tried if t.get("fits")]
    if fits:
        big = fits[0]
        failed = ", ".join(f"{t['nworld']:,}" for t in tried if not t.get("fits"))
        note += (
            f"\n\nLargest batch tried that fits on this GPU: **{big['nworld']:,} worlds** "
            f"({big['bytes_per_world'] / 1e3:.0f} kB of device memory per world, "
            f"{min(big['ms_per_tick']):.0f} ms a tick fresh from home; "
            f"{failed} failed to allocate)."
        )
    return common.md_table(head, rows) + note


def profile() -> str:
    """Section 18 on CUDA: the served tick before (snapshot path) and after (packed path)."""
    tp = _load("tick_profile_cuda.json")
    rows = []
    for key, res in tp.get("results", {}).items():
        for n, r in res.items():
            s = r["seconds_per_s"]
            host = s.get("render") if "snapshot/" in key else s.get("encode")
            rows.append(
                [
                    f"{int(n):,}",
                    key,
                    f"{r['engine_ms_per_tick']:.1f}",
                    f"{r['served_ms_per_tick']:.1f}",
                    common.fmt_ratio(r["served_vs_engine"]),
                    f"{r['frames_per_s']:.1f}",
                    f"{s.get('snapshot', 0):.3f}",
                    f"{s.get('frames', 0):.3f}",
                    f"{host or 0:.2f}",
                ]
            )
    head = list(PROFILE_HEAD)
    return common.md_table(head, rows) + f"\n\n({_machine(tp)})"


def baseline() -> str:
    """Section 17: engine vs raw captured, tick by tick from home."""
    bl = _load("warp_baseline_cuda.json")
    rows = []
    for n, r in bl.get("results", {}).items():
        for k, ms in r["mean_ms_after_first_quarter"].items():
            quarters = " → ".join(f"{x:.1f}" for x in r["window_mean_ms"][k])
            rows.append(
                [
                    f"{int(n):,}",
                    k,
                    f"{ms:.2f}",
                    quarters,
                    common.fmt_ratio(r["engine_vs"].get(k, 1.0)),
                ]
            )
    head = list(BASELINE_HEAD)
    return common.md_table(head, rows) + f"\n\n({_machine(bl)})"


def capacity() -> str:
    """Section 11 on the CPU: real-time capacity per engine and format, against the limit."""
    cap = _load("capacity_engines.json")
    limit = cap.get("limit_worlds")
    rows = []
    for key in ("mujoco", "mujoco_binary", "warp"):
        e = cap.get(key)
        if not e:
            continue
        best = e.get("capacity_worlds")
        cands = e.get("candidates", [])
        top = next((c for c in cands if c["nworld"] == best and c.get("passed")), {})
        above = [c for c in cands if not c.get("passed") and c["nworld"] > (best or 0)]
        nxt = min(above, key=lambda c: c["nworld"]) if above else None
        rows.append(
            [
                key.split("_")[0],
                e.get("format", "json"),
                f"{e['share_held']:g}×" if e.get("share_held") else "–",
                f"{best:,}" if best else "–",
                common.fmt_ratio(top.get("share_of_limit_beside")),
                common.fmt_ratio(best / limit if best and limit else None),
                f"{top['engine_share']:.3f}" if top.get("engine_share") else "–",
                f"{nxt['nworld']:,}, {_rtf(nxt['realtime_factor'])}, "
                f"{common.fmt_ratio(nxt.get('share_of_limit_beside'))}"
                if nxt and nxt.get("realtime_factor")
                else "–",
            ]
        )
    head = list(CAPACITY_HEAD)
    load = cap.get("machine", {}).get("loadavg_at_start")
    best = f"best limit of the run {limit:,.0f} worlds" if limit else "no limit"
    return common.md_table(head, rows) + f"\n\n({_machine(cap)}; {best}; load at start {load})"


CAPACITY_RUNS = common.RESULTS_DIR / "issue20" / "capacity"  # every section 11 run kept
RUNS_HEAD = (
    "run (UTC, code)",
    "limit readings (worlds)",
    "native JSON: rung held (worlds, × beside)",
    "native binary: rung held (worlds, × beside)",
    "warp (worlds)",
)


def _held(e: dict[str, Any] | None) -> str:
    if not e or not e.get("share_held"):
        return "none"
    runs = [c for c in e.get("candidates", []) if c.get("rung") == e["share_held"] and c["counted"]]
    lo, hi = (f"{f(c['share_of_limit_beside'] for c in runs):.2f}" for f in (min, max))
    beside = lo if lo == hi else f"{lo}-{hi}"
    return f"{e['share_held']:g}× ({e['capacity_worlds']:,}, {beside}×)"


def capacity_runs() -> str:
    """Every section 11 run kept in bench/results/issue20/capacity/, one row each: the machine
    drifts, so one run is one sample."""
    rows = []
    for path in sorted(CAPACITY_RUNS.glob("*.json")):
        cap = common.read_json(path.name, CAPACITY_RUNS) or {}
        stamp, commit = path.stem.split("_")  # 2026-11-24T0252_687b2f2
        day, hhmm = stamp.split("T")
        steps = cap["rollout_world_steps_per_s"] / cap["limit_worlds"]  # world-steps per world
        lo, hi = (f(cap["rollout_blocks"]) / steps for f in (min, max))
        warp = cap.get("warp", {}).get("capacity_worlds")
        rows.append(
            [
                f"{day} {hhmm[:2]}:{hhmm[2:]}, `{commit}`",
                f"{lo:,.0f}-{hi:,.0f}",
                _held(cap.get("mujoco")),
                _held(cap.get("mujoco_binary")),
                f"{warp:,}" if warp else "–",
            ]
        )
    return common.md_table(list(RUNS_HEAD), rows)


def headline() -> str:
    """How many worlds in real time, CPU and GPU, as bench/figures.py words it."""
    return figures.headline()


TABLES: dict[str, Callable[[], str]] = {
    "headline": headline,
    "gpu": gpu,
    "profile": profile,
    "baseline": baseline,
    "capacity": capacity,
    "capacity_runs": capacity_runs,
}


def update(text: str) -> str:
    for name, render in TABLES.items():
        pattern = re.compile(rf"(<!-- bench:{name} -->\n)(?:.*?\n)?(<!-- /bench:{name} -->)", re.S)
        if pattern.search(text):
            text = pattern.sub(lambda m, r=render: m.group(1) + r() + "\n" + m.group(2), text)
    return text


def main() -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.readme_tables", description=__doc__)
    ap.add_argument("--check", action="store_true", help="exit 1 if the README is out of date")
    args = ap.parse_args()
    old = README.read_text()
    new = update(old)
    if args.check:
        return int(new != old)
    README.write_text(new)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
