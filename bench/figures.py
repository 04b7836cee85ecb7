"""Figures for prose, and any result file as a table, read from bench/results/*.json.

Why: a number typed into a page goes stale the day the bench runs again. The documentation
site (scripts/docsite) and the README's headline (``python -m bench.readme_tables``) take every
measured figure from here instead, so a figure in prose is always that of a recorded run, with
the machine, date and command that produced it.

    figure("cpu.native_worlds")     # '1,000' (native MuJoCo held at RTF >= 0.99, JSON frames)
    section_table("latency.json")   # the section's own rows, with machine, date and command
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench import common

# Files of the figures of today; older result files (the 2.083 ms physics step, before the
# engines were reworked) stay in bench/results for history but are not shown.
CPU_CAPACITY = "capacity_engines.json"
GPU_THROUGHPUT = "throughput_cuda.json"
GPU_BINARY = "service_fast_binary_cuda.json"
GPU_JSON = "service_fast_cuda.json"
GPU_BASELINE = "warp_baseline_cuda.json"


def load(name: str) -> dict[str, Any]:
    """A result file by name, relative to bench/results (``issue20/engines.json`` works)."""
    path = common.RESULTS_DIR / name
    return common.read_json(path.name, path.parent) or {}


def _int(x: float) -> str:
    return f"{int(x):,}"


def _cores(payload: dict[str, Any]) -> str:
    m = payload.get("machine")
    if not m:
        return payload.get("gpu") or "machine not recorded"
    gpus = m.get("gpus")
    if m.get("gpu") or gpus:
        return m.get("gpu") or f"{len(gpus)}× {gpus[0]}"
    return f"{m.get('cpu_model', '?')}, {m.get('usable_cores') or m.get('cpu_count')} cores"


def command(payload: dict[str, Any]) -> str:
    """The command line that wrote a result file, as a user would type it."""
    if payload.get("commands"):  # a run written by hand: its first command, without remarks
        return payload["commands"][0].split("   ")[0].replace(" --out replay_cuda.json", "")
    argv = list(payload.get("command") or [])
    if not argv:
        if payload.get("number"):
            return f"armfleet bench --section {payload['number']}"
        return f"python -m bench.{payload.get('section', '?')}"
    head, rest = Path(argv[0]).name, argv[1:]
    if "--out" in rest:  # where the run wrote its files is not part of what it measured
        i = rest.index("--out")
        del rest[i : i + 2]
    if head in ("cli.py", "armfleet"):
        words = ["armfleet", *rest]
    elif head == "runner.py":
        words = ["armfleet", "bench", *rest]
    else:
        words = ["python", "-m", f"bench.{head.removesuffix('.py')}", *rest]
    return " ".join(words)


def caption(payload: dict[str, Any]) -> str:
    """Machine, date and command of a result file, one line under its table."""
    date = str(payload.get("started") or payload.get("date", "?")).replace("T", " ")[:16]
    return f"*{_cores(payload)}, {date} UTC; `{command(payload)}`*"


def _served(name: str) -> dict[str, Any]:
    results = load(name).get("results", {})
    return results[max(results, key=int)] if results else {}


def _gpu_realtime_worlds() -> str:
    """Worlds an H100 keeps at 60 Hz while streaming all of them: the served world-steps/s of
    the largest batch measured, over the world-steps one world needs a second."""
    top = _served(GPU_BINARY)
    steps = top["world_steps_per_s"] / (common.CONTROL_HZ * top["substeps"])
    return f"{math.floor(steps / 1000) * 1000:,}"


def _gpu(nworld: str, key: str, name: str = GPU_BINARY) -> Callable[[], str]:
    return lambda: common.fmt_ratio(load(name)["results"][nworld][key])


def _cpu(engine: str, key: str = "capacity_worlds") -> Callable[[], str]:
    return lambda: _int(load(CPU_CAPACITY)[engine][key])


def _per_core() -> str:
    cap = load(CPU_CAPACITY)
    return _int(cap["mujoco"]["capacity_worlds"] / cap["machine"]["usable_cores"])


def _largest_fit() -> str:
    fits = [t for t in load(GPU_BASELINE).get("largest", []) if t.get("fits")]
    return _int(fits[0]["nworld"])


def _ray_rt() -> dict[str, Any]:
    """The Ray round trip per tick at 60 Hz, on the smallest batch (the cost of Ray alone)."""
    rt = load("ray_cuda.json")["rt"]
    return rt[min(rt, key=int)]


def _ur(part: str, key: str, fmt: str = "{}") -> Callable[[], str]:
    """A figure of section 32's last run (bench/ur_programs.py): `part` programs or receive."""
    return lambda: fmt.format(load("ur_programs.json")[part][key])


def _ur_load() -> str:
    runs = [load("ur_programs.json")[part] for part in ("programs", "receive")]
    loads = [r[k] for r in runs for k in ("load_1m_at_start", "load_1m_at_end")]
    return f"{min(loads):.0f} to {max(loads):.0f}"


def _replay_rate(mode: str) -> float:
    return load("replay_cuda.json")["modes"][mode]["rate"]["ticks_per_s"]


FIGURES: dict[str, Callable[[], str]] = {
    "cpu.machine": lambda: _cores(load(CPU_CAPACITY)),
    "cpu.date": lambda: load(CPU_CAPACITY)["started"][:10],
    "cpu.native_worlds": _cpu("mujoco"),
    "cpu.native_binary_worlds": _cpu("mujoco_binary"),
    "cpu.warp_worlds": _cpu("warp"),
    "cpu.native_per_core": _per_core,
    "cpu.limit_worlds": lambda: _int(load(CPU_CAPACITY)["limit_worlds"]),
    "cpu.native_share": lambda: common.fmt_ratio(load(CPU_CAPACITY)["mujoco"]["share_held"]),
    # Capacity as a ratio to the rollout limit of the same run (the best limit reading): what
    # carries to another machine, where the limit itself differs (`armfleet capacity`).
    "cpu.native_ratio": lambda: common.fmt_ratio(load(CPU_CAPACITY)["mujoco"]["capacity_vs_limit"]),
    "cpu.native_binary_ratio": lambda: common.fmt_ratio(
        load(CPU_CAPACITY)["mujoco_binary"]["capacity_vs_limit"]
    ),
    "cpu.warp_ratio": lambda: common.fmt_ratio(load(CPU_CAPACITY)["warp"]["capacity_vs_limit"]),
    "gpu.machine": lambda: _cores(load(GPU_BINARY)),
    "gpu.date": lambda: load(GPU_BINARY)["started"][:10],
    "gpu.realtime_worlds": _gpu_realtime_worlds,
    "gpu.largest_worlds": lambda: _int(max(load(GPU_BINARY)["results"], key=int)),
    "gpu.largest_ticks_per_s": lambda: f"{_served(GPU_BINARY)['ticks_per_s']:.0f}",
    "gpu.binary_16384": _gpu("16384", "ratio_to_engine"),
    "gpu.binary_65536": _gpu("65536", "ratio_to_engine"),
    "gpu.json_16384": _gpu("16384", "ratio_to_engine", GPU_JSON),
    "gpu.largest_fit": _largest_fit,
    "ray.steps_two_vs_one": lambda: common.fmt_ratio(load("ray_cuda.json")["steps_scaling"]),
    "ray.steps_two_vs_in_process": lambda: common.fmt_ratio(
        load("ray_cuda.json")["steps_scaling_vs_in_process"]
    ),
    "ray.snapshots_two_vs_one": lambda: common.fmt_ratio(load("ray_cuda.json")["scaling"]),
    "ray.snapshots_two_vs_in_process": lambda: common.fmt_ratio(
        load("ray_cuda.json")["scaling_vs_in_process"]
    ),
    "ray.round_trip_p50_ms": lambda: f"{_ray_rt()['ray_overhead']['p50_ms']:.1f}",
    "ray.round_trip_p99_ms": lambda: f"{_ray_rt()['ray_overhead']['p99_ms']:.1f}",
    "ray.gpu_rebuild_s": lambda: f"{load('ray_cuda.json')['loss']['rebuild_s']:.1f}",
    "ray.host_recover_s": lambda: f"{load('ray_hosts.json')['rows'][0]['recover s']:.1f}",
    "ur.load": _ur_load,
    "ur.programs_ok": lambda: "{ok}/{programs}".format(**load("ur_programs.json")["programs"]),
    "ur.programs_rtf": _ur("programs", "rtf", "{:.2f}"),
    "ur.programs_service_cores": _ur("programs", "service_cpu", "{:.2f}"),
    "ur.programs_client_cores": _ur("programs", "programs_cpu", "{:.2f}"),
    "ur.command_p50_ms": lambda: (
        f"{load('ur_programs.json')['programs']['latency_ms']['command']['p50']:.0f}"
    ),
    "ur.receive_hz": _ur("receive", "rate_median", "{:.0f}"),
    "ur.receive_rtf": _ur("receive", "rtf", "{:.2f}"),
    "cuda_replay.default_ticks_per_s": lambda: f"{_replay_rate('default'):.0f}",
    "cuda_replay.atomics_ticks_per_s": lambda: f"{_replay_rate('atomics'):.0f}",
    "cuda_replay.atomics_slower": lambda: (
        f"{_replay_rate('default') / _replay_rate('atomics'):.1f}×"
    ),
    "cuda_replay.divergence": lambda: load("replay_cuda.json")["modes"]["default"]["replay"][
        "divergence"
    ],
}


def figure(name: str) -> str:
    """One figure by name; KeyError names the known ones when it is not one of them."""
    if name not in FIGURES:
        raise KeyError(f"unknown figure {name!r}; known: {', '.join(sorted(FIGURES))}")
    return FIGURES[name]()


def _cell(key: str, value: Any) -> str:
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int | float) and (
        "world-steps" in key or (isinstance(value, float) and abs(value) >= 1e5)
    ):
        return common.fmt_rate(value)
    if isinstance(value, float):
        if abs(value) >= 100:
            return f"{value:,.0f}"
        return f"{value:.3g}"
    if isinstance(value, int):
        return f"{value:,}" if abs(value) >= 10_000 else str(value)
    return str(value).replace("|", "\\|")


def _http_rows(payload: dict[str, Any]) -> list[dict[str, Any]]:
    """Section 5 keeps its runs by client; one row each."""
    rows = []
    for key, r in payload.get("results", {}).items():
        client = "wrk" if key.startswith("wrk/") else "Python httpx"
        rows.append(
            {
                "client": client,
                "keep-alive connections": int(key.split("/")[-1]),
                "requests/s": r["requests_per_s"],
                "p50 ms": r["latency"]["p50_ms"],
                "p99 ms": r["latency"]["p99_ms"],
            }
        )
    return rows


def _result_rows(payload: dict[str, Any]) -> list[dict[str, Any]]:
    """A run kept as one ``result`` object (the soak): one row per measure."""
    rows = []
    for key, value in payload.get("result", {}).items():
        if isinstance(value, dict):
            rows += [{"measure": f"{key} {k}", "value": v} for k, v in value.items() if k != "n"]
        elif not isinstance(value, list):
            rows.append({"measure": key, "value": value})
    return rows


def _replay_rows(payload: dict[str, Any]) -> list[dict[str, Any]]:
    """The CUDA determinism probe: two runs of the same commands, compared by tick range."""
    probe = payload.get("modes", {}).get("default", {}).get("probe", {})
    return [
        {
            "ticks": r["ticks"],
            "worlds differing": r["worlds_differing"],
            "largest |Δposition| rad": r["max_abs_position"],
            "largest |Δvelocity| rad/s": r["max_abs_velocity"],
            "largest |Δeffort| N·m": r["max_abs_effort"],
        }
        for r in probe.get("ranges", [])
    ]


def section_table(name: str) -> str:
    """A result file's ``rows`` as a Markdown table, its notes and its caption."""
    payload = load(name)
    rows = (
        payload.get("rows") or _http_rows(payload) or _result_rows(payload) or _replay_rows(payload)
    )
    if not rows:
        raise KeyError(f"{name}: no rows to show")
    head: list[str] = []
    for row in rows:
        head += [k for k in row if k not in head]
    body = [[_cell(k, row.get(k)) for k in head] for row in rows]
    names = [k.replace("|", "\\|") for k in head]
    lines = [common.md_table(names, body), "", caption(payload)]
    lines += [f"\n{note}" for note in payload.get("notes") or []]
    return "\n".join(lines)


def headline() -> str:
    """The answer to "how many worlds in real time?", for the README and the site."""
    f = figure
    return (
        f"- **CPU**: native MuJoCo (`--engine mujoco`) holds **{f('cpu.native_ratio')} of the "
        f"rollout limit** at 60 Hz in real time with every world streamed as JSON "
        f"({f('cpu.native_binary_ratio')} in binary), MuJoCo Warp on the CPU "
        f"{f('cpu.warp_ratio')}. The limit is how many worlds raw `mujoco.rollout` of the "
        f"same model steps at 60 Hz on all cores, and it is the machine's: measured on "
        f"{f('cpu.machine')} ({f('cpu.date')}), it was {f('cpu.limit_worlds')} worlds, so "
        f"{f('cpu.native_worlds')} native and {f('cpu.warp_worlds')} Warp worlds there. "
        f"`armfleet capacity` measures yours in about a minute.\n"
        f"- **GPU** ({f('gpu.machine')}): MuJoCo Warp serves {f('gpu.largest_worlds')} worlds "
        f"at {f('gpu.largest_ticks_per_s')} ticks/s in fast mode, every world streamed in "
        f"binary; at that rate about **{f('gpu.realtime_worlds')} worlds** keep 60 Hz. The "
        f"largest batch that fits is {f('gpu.largest_fit')} worlds."
    )
