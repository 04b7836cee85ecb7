"""`armfleet bench`: run the sections in order, write bench/results/, print the tables.

CPU (default): 1 throughput, 2 service fast mode, 3 realtime capacity, 4 WebSocket latency,
5 HTTP, 6 cold/warm start. ``--device cuda``: sections 1 and 2 on the GPU (1024..65536
worlds; native MuJoCo still on the CPU cores), written as ``*_cuda.json`` / ``throughput_cuda.png``
so that they do not replace the CPU results.

Every section writes its own JSON as soon as it is done (bench/results/<section>.json); the
whole run also goes to bench/results/results.json with machine info, the command and timestamps.
A section that fails is recorded with its error and the others still run.

Standalone: ``python -m bench.suite [--quick] [--device cuda] [--sections 1 2]``.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import sys
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from bench import common

ALL_SECTIONS = (1, 2, 3, 4, 5, 6)
GPU_SECTIONS = (1, 2)
NAMES = {
    1: "throughput",
    2: "service_fast",
    3: "realtime_capacity",
    4: "latency",
    5: "http",
    6: "startup",
}


def _say(msg: str) -> None:
    print(msg, flush=True)


@contextlib.contextmanager
def _section(
    k: int, title: str, report: dict[str, Any], timings: dict[str, float]
) -> Iterator[None]:
    _say(f"[{k}] {title} ...")
    t0 = time.perf_counter()
    try:
        yield
    except Exception as exc:
        report.setdefault("errors", {})[NAMES[k]] = "".join(
            traceback.format_exception_only(type(exc), exc)
        ).strip()
        _say(f"[{k}] FAILED: {type(exc).__name__}: {exc}")
    finally:
        took = time.perf_counter() - t0
        timings[NAMES[k]] = round(timings.get(NAMES[k], 0.0) + took, 1)
        gc.collect()
        _say(f"[{k}] done in {took:.0f} s")


def run_suite(
    quick: bool = False,
    device: str = "cpu",
    sections: Sequence[int] | None = None,
    results_dir: Path | None = None,
) -> dict[str, Any]:
    """Run the benchmark; returns what it wrote to results.json (results_<device>.json)."""
    from bench import http_bench, latency, plot, service_bench, startup, throughput

    cuda = device.startswith("cuda")
    if cuda and not throughput.cuda_available():
        print(
            f"armfleet bench: --device {device} needs an NVIDIA GPU with a working CUDA driver, "
            "and Warp finds none on this machine. Nothing was run; use --device cpu here.",
            file=sys.stderr,
        )
        raise SystemExit(2)
    wanted = list(sections or (GPU_SECTIONS if cuda else ALL_SECTIONS))
    if cuda:
        skipped = [s for s in wanted if s not in GPU_SECTIONS]
        if skipped:
            _say(f"--device {device}: sections {skipped} are CPU-only here; skipping them")
        wanted = [s for s in wanted if s in GPU_SECTIONS]
    suffix = common.suffix_for(device)
    out_dir = results_dir or common.RESULTS_DIR
    mode = "quick" if quick else "full"

    def write(name: str, payload: dict[str, Any]) -> None:
        common.write_json(f"{name}{suffix}.json", payload, out_dir)

    t_start = time.perf_counter()
    report: dict[str, Any] = {
        "suite": "armfleet bench",
        "mode": mode,
        "device": device,
        "sections_run": wanted,
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]],
        "started": common.now_iso(),
        "machine": common.machine_info(device),
        "sections": {},
    }
    timings: dict[str, float] = {}
    report["section_seconds"] = timings
    res = report["sections"]
    _say(
        f"armfleet bench ({mode}, {device}) on {report['machine']['cpu_model']}, "
        f"{report['machine']['usable_cores']} cores; results → {out_dir}"
    )

    if 1 in wanted:
        with _section(1, "throughput: engine vs raw MuJoCo Warp vs native MuJoCo", report, timings):
            d = throughput.defaults(quick, device)
            res["throughput"] = throughput.run(
                d["sizes"], device, d["min_time"], d["warmup_time"], progress=_say
            )
            write("throughput", res["throughput"])
    tp = res.get("throughput") or common.read_json(f"throughput{suffix}.json", out_dir)

    if 2 in wanted:
        with _section(2, "service in fast mode, all worlds streamed at 30 Hz", report, timings):
            d = service_bench.defaults_fast(quick, device)
            res["service_fast"] = service_bench.run_fast(
                d["sizes"], device, d["duration"], d["warmup"], throughput=tp, progress=_say
            )
            write("service_fast", res["service_fast"])

    if 3 in wanted:
        with _section(3, "real-time capacity (RTF >= 0.99)", report, timings):
            d = service_bench.defaults_capacity(quick)
            start = service_bench.start_from_throughput(tp)
            res["realtime_capacity"] = service_bench.run_capacity(
                device, d["window"], d["warmup"], d["refine"], start=start, progress=_say
            )
            write("realtime_capacity", res["realtime_capacity"])

    if 4 in wanted or 5 in wanted:
        # Latency at 16 worlds and the HTTP section share one 16-world realtime server; it is
        # stopped before latency runs at the other sizes, so no idle server competes with them.
        d4 = latency.defaults(quick)
        d5 = http_bench.defaults(quick)
        shared_n = d5["worlds"]
        servers: dict[int, common.Server] = {}
        parts: list[dict[str, Any]] = []
        with contextlib.ExitStack() as stack:
            with contextlib.suppress(Exception):
                servers[shared_n] = stack.enter_context(
                    common.running_server(shared_n, "realtime", device)
                )
            if 4 in wanted and shared_n in d4["sizes"]:
                with _section(4, "WebSocket command latency (realtime mode)", report, timings):
                    parts.append(
                        latency.run(
                            [shared_n],
                            d4["commands"],
                            d4["controllers"],
                            device,
                            servers=servers,
                            progress=_say,
                        )
                    )
            if 5 in wanted:
                with _section(5, "HTTP increments, 1 and 8 clients", report, timings):
                    res["http"] = http_bench.run(
                        shared_n,
                        d5["duration"],
                        d5["warmup"],
                        device=device,
                        server=servers.get(shared_n),
                        progress=_say,
                    )
                    write("http", res["http"])
        rest = [n for n in d4["sizes"] if n != shared_n]
        if 4 in wanted and rest:
            with _section(4, "WebSocket command latency, larger batches", report, timings):
                parts.append(
                    latency.run(rest, d4["commands"], d4["controllers"], device, progress=_say)
                )
        if parts:
            merged = {**parts[0], "sizes": list(d4["sizes"]), "finished": parts[-1]["finished"]}
            merged["results"] = {k: v for p in parts for k, v in p["results"].items()}
            merged["errors"] = {k: v for p in parts for k, v in p["errors"].items()}
            res["latency"] = merged
            write("latency", merged)

    if 6 in wanted:
        with _section(6, "cold and warm start → /readyz", report, timings):
            d = startup.defaults(quick)
            res["startup"] = startup.run(16, d["repeats"], d["cold"], device, progress=_say)
            write("startup", res["startup"])

    png: Path | None = None
    if "throughput" in res or "service_fast" in res:
        with contextlib.suppress(Exception):
            cap = res.get("realtime_capacity", {}).get("capacity_worlds")
            png = plot.plot(
                res.get("throughput"),
                res.get("service_fast"),
                out_dir / f"throughput{suffix}.png",
                cap,
            )
    report["plot"] = str(png) if png else None
    if set(wanted) != set(GPU_SECTIONS if cuda else ALL_SECTIONS):
        # A partial run keeps the other sections of the last results file (each section carries
        # its own machine info and timestamps).
        earlier = common.read_json(f"results{suffix}.json", out_dir) or {}
        kept = {k: v for k, v in (earlier.get("sections") or {}).items() if k not in res}
        if kept:
            report["sections"] = res = {**kept, **res}
            report["kept_from_earlier_run"] = sorted(kept)
    report["finished"] = common.now_iso()
    report["total_seconds"] = round(time.perf_counter() - t_start, 1)
    path = common.write_json(f"results{suffix}.json", report, out_dir)
    print_tables(report)
    _say(f"\nwrote {path}" + (f" and {png}" if png else "") + f" in {report['total_seconds']} s")
    return report


def print_tables(report: dict[str, Any]) -> None:
    from bench import http_bench, latency, service_bench, startup, throughput

    console = common.console()
    makers: dict[str, Callable[[dict[str, Any]], Any]] = {
        "throughput": throughput.table,
        "service_fast": service_bench.table_fast,
        "realtime_capacity": service_bench.table_capacity,
        "latency": latency.table,
        "http": http_bench.table,
        "startup": startup.table,
    }
    console.print()
    m = report["machine"]
    console.print(
        f"[bold]armfleet bench[/bold] ({report['mode']}, {report['device']}): {m['cpu_model']}, "
        f"{m['usable_cores']} cores, load {m.get('loadavg_at_start')} at start; python "
        f"{m['python']}, mujoco {m['mujoco']}, mujoco-warp {m['mujoco_warp']}, warp {m['warp']}"
    )
    for name, make in makers.items():
        payload = report["sections"].get(name)
        if payload:
            console.print(make(payload))
            for where, err in (payload.get("errors") or {}).items():
                console.print(f"  [red]{name} {where}: {err}[/red]")
    for name, err in (report.get("errors") or {}).items():
        console.print(f"[red]section {name} failed: {err}[/red]")


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.suite", description=__doc__)
    p.add_argument("--quick", action="store_true", help="smaller sizes and shorter runs")
    p.add_argument("--device", default="cpu", help="cpu or cuda")
    p.add_argument("--sections", type=int, nargs="+", choices=ALL_SECTIONS)
    args = p.parse_args(argv)
    report = run_suite(args.quick, args.device, args.sections)
    return 1 if report.get("errors") else 0


if __name__ == "__main__":
    raise SystemExit(main())
