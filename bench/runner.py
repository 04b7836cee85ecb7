"""`armfleet bench`: run the chosen sections, print their tables, write bench/results/.

Each section writes ``bench/results/<name>.json`` (``<name>_cuda.json`` for ``--device cuda``, so
GPU runs never replace the CPU files) as soon as it is done: the section's rows and detail inside
an envelope saying what ran, where and when. The whole run goes to ``results.json``; a run of some
sections keeps the other sections of the last one. After the throughput or service sections the
plot (``throughput.png``) is redrawn from the result files. A section that fails is recorded with
its error and the others still run.

``python -m bench.runner`` and ``python -m bench.<module>`` (that module's sections) take the
same flags as ``armfleet bench``: ``--section N`` (repeatable), ``--quick``, ``--device``,
``--worlds``, ``--out``, ``--list``.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from bench import common
from bench.registry import Context, Result, Section, device_kind, discover

PLOTTED = {"throughput", "service_fast", "realtime_capacity"}


def choose(
    sections: dict[int, Section], wanted: Sequence[int] | None, device: str, say=print
) -> list[Section]:
    """The sections to run: `wanted` (those that can run on `device`), else the device's default."""
    if not wanted:
        return [s for s in sections.values() if device_kind(device) in s.default_on]
    unknown = sorted(set(wanted) - set(sections))
    if unknown:
        raise SystemExit(f"armfleet bench: no section {unknown}; --list shows them")
    chosen = [sections[k] for k in sorted(set(wanted))]
    skipped = [s.number for s in chosen if not s.runs_on(device)]
    if skipped:
        say(f"--device {device}: sections {skipped} do not run there; skipping them")
    return [s for s in chosen if s.runs_on(device)]


def run_section(sec: Section, ctx: Context) -> dict[str, Any]:
    """Run one section; its payload (envelope + data + rows + notes), also written to its file."""
    started = common.now_iso()
    result = sec.fn(ctx)
    if not isinstance(result, Result):
        raise TypeError(f"section {sec.number} returned {type(result).__name__}, not Result")
    payload = {
        "section": sec.name,
        "number": sec.number,
        "title": sec.title,
        "quick": ctx.quick,
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]],
        "started": started,
        "finished": common.now_iso(),
        "machine": common.machine_info(ctx.device),
        "device": ctx.device,
        **result.data,
        "rows": result.rows,
        "notes": result.notes,
    }
    common.write_json(f"{sec.name}{ctx.suffix}.json", payload, ctx.out_dir)
    ctx.done[sec.name] = payload
    return payload


def run(
    sections: Sequence[int] | None = None,
    quick: bool = False,
    device: str = "cpu",
    worlds: Sequence[int] | None = None,
    out_dir: Path | None = None,
    say: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run `sections` (None: the device's defaults); returns what went to results[_cuda].json."""
    say = say or (lambda msg: print(msg, flush=True))
    if device.startswith("cuda") and not common.cuda_available():
        print(
            f"armfleet bench: --device {device} needs an NVIDIA GPU with a working CUDA driver, "
            "and Warp finds none on this machine. Nothing was run; use --device cpu here.",
            file=sys.stderr,
        )
        raise SystemExit(2)
    chosen = choose(discover(), sections, device, say)
    ctx = Context(quick, device, out_dir or common.RESULTS_DIR, worlds, say)
    mode = "quick" if quick else "full"
    t_start = time.perf_counter()
    report: dict[str, Any] = {
        "suite": "armfleet bench",
        "mode": mode,
        "device": device,
        "sections_run": [s.number for s in chosen],
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]],
        "started": common.now_iso(),
        "machine": common.machine_info(device),
        "sections": ctx.done,
        "section_seconds": {},
        "errors": {},
    }
    m = report["machine"]
    say(
        f"armfleet bench ({mode}, {device}) on {m['cpu_model']}, {m['usable_cores']} cores; "
        f"results → {ctx.out_dir}"
    )
    for sec in chosen:
        say(f"[{sec.number}] {sec.title} ...")
        t0 = time.perf_counter()
        try:
            run_section(sec, ctx)
        except Exception as exc:
            err = "".join(traceback.format_exception_only(type(exc), exc)).strip()
            report["errors"][sec.name] = err
            say(f"[{sec.number}] FAILED: {err}")
        took = time.perf_counter() - t0
        report["section_seconds"][sec.name] = round(took, 1)
        gc.collect()
        say(f"[{sec.number}] done in {took:.0f} s")

    png = None
    if PLOTTED & set(ctx.done):
        from bench import plot

        try:
            png = plot.redraw(ctx.out_dir, device)
        except Exception as exc:  # e.g. matplotlib missing: the numbers are still written
            say(f"plot not drawn: {type(exc).__name__}: {exc}")
    report["plot"] = str(png) if png else None
    earlier = common.read_json(f"results{ctx.suffix}.json", ctx.out_dir) or {}
    kept = {k: v for k, v in (earlier.get("sections") or {}).items() if k not in ctx.done}
    if kept:  # a partial run keeps the other sections of the last one (each has its own envelope)
        report["sections"] = {**kept, **ctx.done}
        report["kept_from_earlier_run"] = sorted(kept)
    report["finished"] = common.now_iso()
    report["total_seconds"] = round(time.perf_counter() - t_start, 1)
    path = common.write_json(f"results{ctx.suffix}.json", report, ctx.out_dir)
    print_report(report, [s.name for s in chosen])
    say(f"\nwrote {path}" + (f" and {png}" if png else "") + f" in {report['total_seconds']} s")
    return report


def table(payload: dict[str, Any]):
    """The rich Table of a section payload's rows."""
    from rich import box
    from rich.table import Table

    t = Table(
        title=f"{payload['number']}. {payload['title']} ({payload['device']})",
        box=box.SIMPLE_HEAD,
    )
    rows = payload.get("rows") or []
    columns = list(dict.fromkeys(k for row in rows for k in row))
    for col in columns:
        t.add_column(col, justify="right")
    for row in rows:
        t.add_row(*(common.cell(row.get(col)) for col in columns))
    return t


def print_report(report: dict[str, Any], names: Sequence[str]) -> None:
    """The machine line, then each section's table, notes and errors, in run order."""
    console = common.console()
    m = report["machine"]
    console.print()
    console.print(
        f"[bold]armfleet bench[/bold] ({report['mode']}, {report['device']}): {m['cpu_model']}, "
        f"{m['usable_cores']} cores, load {m.get('loadavg_at_start')} at start; python "
        f"{m['python']}, mujoco {m['mujoco']}, mujoco-warp {m['mujoco_warp']}, warp {m['warp']}"
    )
    for name in names:
        payload = report["sections"].get(name)
        if payload and payload.get("number") is not None:
            console.print(table(payload))
            for note in payload.get("notes") or []:
                console.print(f"  {note}")
            for where, err in (payload.get("errors") or {}).items():
                console.print(f"  [red]{name} {where}: {err}[/red]")
    for name, err in report["errors"].items():
        console.print(f"[red]section {name} failed: {err}[/red]")


def listing(sections: dict[int, Section]) -> str:
    lines = []
    for s in sections.values():
        lines.append(
            f"{s.number:>3}  {s.name:<22} {s.title}  [{', '.join(s.devices)}; "
            f"default on {', '.join(s.default_on) or 'none'}] ({s.module})"
        )
    return "\n".join(lines)


def parser(prog: str, description: str | None) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=description)
    p.add_argument(
        "--section", type=int, action="append", help="run this section (repeatable; see --list)"
    )
    p.add_argument("--quick", action="store_true", help="smaller sizes and shorter runs")
    p.add_argument("--device", default="cpu", help="cpu or cuda[:N]")
    p.add_argument(
        "--worlds",
        type=int,
        action="append",
        help="batch size instead of the sections' (repeatable)",
    )
    p.add_argument("--out", type=Path, help="results folder (default bench/results)")
    p.add_argument("--list", action="store_true", help="list the sections and exit")
    return p


def main(argv: Sequence[str] | None = None, module: str | None = None) -> int:
    """Command line of the runner, or of one section module (`module`: its sections only)."""
    if module == "__main__":
        module = sys.modules["__main__"].__spec__.name
    sections = discover()
    own = {k: s for k, s in sections.items() if module in (None, s.module)}
    prog = f"python -m {module or 'bench.runner'}"
    args = parser(prog, sys.modules[module or __name__].__doc__).parse_args(argv)
    if args.list:
        print(listing(own))
        return 0
    wanted = args.section
    if module:
        kind = device_kind(args.device)
        wanted = wanted or [k for k, s in own.items() if kind in s.default_on]
        if not wanted or set(wanted) - set(own):
            print(f"{prog}: its sections are {list(own)}; --list says where they run")
            return 2
    report = run(wanted, args.quick, args.device, args.worlds, args.out)
    ran = [p for p in report["sections"].values() if p.get("number") in report["sections_run"]]
    failed = report["errors"] or any(p.get("errors") for p in ran)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
