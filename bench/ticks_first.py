"""Ticks first under load: the soak's 200 WebSocket clients (1,000 commands/s in all) on 64
worlds of the default engine, served once with `--no-ticks-first` and once with `--ticks-first`.

Why both in one section: the box is shared and its load moves; the two runs follow each other
and report their load beside their figures, so the ratio says what ticks-first changes. The
clients run in this process, the service in its own (`common.served`), on the same machine.

Per run: the ticks' real-time factor with no commands first (`IDLE_S`: what the box gives the
ticks then), then over the whole load window (ticks stepped / wall time) and its lowest 1 s
sample; commands sent and acked; replies lost, duplicated or out of order (the soak's checks,
final targets included); refusals (client side, and `/metrics`'
`armfleet_commands_total{result="refused"}`); commands that waited for a later tick
(`armfleet_command_waits`); ack latency. ARMFLEET_TICKS_FIRST_DURATION sets the seconds of
load per run (default 30; 20 with --quick). ARMFLEET_BENCH_AGAINST=<revision> adds a first run
of that revision's tree (checked out in a temporary worktree), e.g. the tree before ticks-first.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import time
from pathlib import Path
from typing import Any

import httpx

from bench import common, cpu_meter
from bench.code_vs import checkout
from bench.registry import Context, Result, section

DURATION_ENV = "ARMFLEET_TICKS_FIRST_DURATION"
AGAINST_ENV = "ARMFLEET_BENCH_AGAINST"  # a revision before ticks-first, served as a third run
CLIENTS, WORLDS, RATE = 200, 64, 5.0  # 1,000 commands/s in all
IDLE_S = 8.0  # the ticks' pace with no commands, measured first on the same service
CORES = ("cores_server", "cores_workers", "cores_clients", "cores_others", "cores_idle")


def metric(text: str, name: str, **labels: str) -> float:
    """The sum of the Prometheus series `name` whose labels include `labels`."""
    total = 0.0
    for line in text.splitlines():
        if not line.startswith(name) or line.startswith("#"):
            continue
        head, _, value = line.rpartition(" ")
        series, _, rest = head.partition("{")
        if series != name or any(f'{k}="{v}"' not in rest for k, v in labels.items()):
            continue
        total += float(value)
    return total


def tick_parts(first: str, last: str, wall: float) -> dict[str, float | None]:
    """Where a tick's wall time went between two /metrics texts `wall` seconds apart: the
    engine's step, the loop's own work around it (commands in, snapshot, frames; waiting for
    the GIL included), and the period between two ticks (1000/60 ms when on time)."""
    ticks = metric(last, "armfleet_tick_duration_seconds_count") - metric(
        first, "armfleet_tick_duration_seconds_count"
    )
    if not ticks:
        return {"step_ms": None, "loop_ms": None, "period_ms": None}
    step = metric(last, "armfleet_engine_step_seconds_total") - metric(
        first, "armfleet_engine_step_seconds_total"
    )
    tick = metric(last, "armfleet_tick_duration_seconds_sum") - metric(
        first, "armfleet_tick_duration_seconds_sum"
    )
    return {
        "step_ms": round(1e3 * step / ticks, 2),
        "loop_ms": round(1e3 * (tick - step) / ticks, 2),
        "period_ms": round(1e3 * wall / ticks, 2),
    }


def one_run(
    ticks_first: bool | None, duration: float, device: str, say: Any, cwd: Path | None = None
) -> dict[str, Any]:
    """The load against a fresh service with ticks-first on or off (None: a tree without it,
    served from `cwd`)."""
    from bench.soak import soak

    env = {} if ticks_first is None else {"ARMFLEET_TICKS_FIRST": str(ticks_first).lower()}
    with common.served(WORLDS, "realtime", device, env=env, cwd=cwd) as srv:
        load = os.getloadavg()[0]
        say(f"  ticks-first {ticks_first}: load {load:.2f}, {duration:g} s")
        # The same service with no commands first: what the box gives the ticks right now.
        pid = srv.server.process.pid
        before, cpu0 = srv.get_info(), cpu_meter.read(pid)
        time.sleep(IDLE_S)
        after, cpu1 = srv.get_info(), cpu_meter.read(pid)
        idle = common.rtf_between(before, after)
        idle_cpu = cpu_meter.between(cpu0, cpu1, after[1]["tick"] - before[1]["tick"])
        first = httpx.get(f"{srv.url}/metrics", timeout=30).text
        result = asyncio.run(soak(srv.url, CLIENTS, WORLDS, RATE, duration, pid, warmup=3.0))
        end, cpu2 = srv.get_info(), cpu_meter.read(pid)  # the load window and its warm-up
        load_cpu = cpu_meter.between(cpu1, cpu2, end[1]["tick"] - after[1]["tick"])
        text = httpx.get(f"{srv.url}/metrics", timeout=30).text
        load_cpu |= tick_parts(first, text, end[0] - after[0])
    idle_tick_ms = (idle_cpu["server_ms_per_tick"] or 0) + (idle_cpu["workers_ms_per_tick"] or 0)
    costs = cpu_meter.per_command(
        idle_cpu, load_cpu, result.acks + result.refused, result.commands_sent
    )
    need = None  # cores the target load needs: 60 ticks/s and 1,000 commands/s at these costs
    if costs["server_ms_per_command"] is not None and costs["clients_ms_per_command"]:
        per_s = CLIENTS * RATE * (costs["server_ms_per_command"] + costs["clients_ms_per_command"])
        need = round((idle_tick_ms * srv.info["control_hz"] + per_s) / 1e3, 2)
    return {
        **costs,
        "cores_needed": need,
        "shards": srv.info.get("shards"),
        # what a tick costs the server and its engine workers with no commands (CPU ms)
        "tick_cpu_ms_idle": round(idle_tick_ms, 2),
        "cpu_idle": idle_cpu,
        "cpu_load": load_cpu,  # cores each party used under load, and CPU ms per tick
        "ticks_first": ticks_first,
        "load_1m_at_start": round(load, 2),
        "load_1m_at_end": round(os.getloadavg()[0], 2),
        "rtf_idle": round(idle, 3),
        "rtf": result.rtf_window,
        "rtf_of_idle": None if not result.rtf_window else round(result.rtf_window / idle, 3),
        "rtf_min": result.rtf_min,
        "sent": result.commands_sent,
        "acks": result.acks,
        "refused": result.refused,
        "refused_metrics": int(metric(text, "armfleet_commands_total", result="refused")),
        "waits": int(metric(text, "armfleet_command_waits_total")),
        "lost": result.missing,
        "duplicates": result.duplicates,
        "out_of_order": result.out_of_order,
        "worlds_wrong": result.worlds_wrong,
        "ack_p50_ms": result.ack_latency["p50_ms"],
        "ack_p99_ms": result.ack_latency["p99_ms"],
        "accepted_per_s": round(result.acks / result.duration_s, 1),
        "problems": result.problems,
    }


def _row(name: str, r: dict[str, Any]) -> dict[str, Any]:
    return {
        "run": name,
        "load 1m": f"{r['load_1m_at_start']:.1f}→{r['load_1m_at_end']:.1f}",
        "RTF idle": r["rtf_idle"],
        "RTF": r["rtf"],
        "RTF/idle": r["rtf_of_idle"],
        "RTF min 1 s": r["rtf_min"],
        "sent": r["sent"],
        "acked": r["acks"],
        "acked/s": r["accepted_per_s"],
        "refused (client/metrics)": f"{r['refused']}/{r['refused_metrics']}",
        "lost/dup/reordered": f"{r['lost']}/{r['duplicates']}/{r['out_of_order']}",
        "waited": r["waits"],
        "ack p50/p99 ms": f"{r['ack_p50_ms']}/{r['ack_p99_ms']}",
        "tick CPU ms idle": r["tick_cpu_ms_idle"],
        "command CPU ms server/clients": f"{r['server_ms_per_command']}/"
        f"{r['clients_ms_per_command']}",
        "cores needed": r["cores_needed"],
        "tick ms: step/loop/period": "/".join(
            str(r["cpu_load"][k]) for k in ("step_ms", "loop_ms", "period_ms")
        ),
        "cores server/workers/clients/others/idle": "/".join(
            f"{r['cpu_load'][k]:.2f}" for k in CORES
        ),
    }


def _ratio(on: Any, off: Any) -> str:
    return "—" if not on or not off else f"{on / off:.2f}×"


@section(31, "ticks_first", default_on=())
def ticks_first_section(ctx: Context) -> Result:
    """Ticks first under load: 200 WebSocket clients, 1,000 commands/s, 64 worlds, off vs on

    Both runs, side by side, and their ratios (on / off)."""
    duration = float(os.environ.get(DURATION_ENV) or ctx.pick(30.0, 20.0))
    runs: dict[str, dict[str, Any]] = {}
    errors: dict[str, str] = {}
    against = os.environ.get(AGAINST_ENV)
    plan: list[tuple[str, bool | None]] = [("off", False), ("on", True)]
    for name, on in [(f"at {against}", None)] * bool(against) + plan:
        try:
            with contextlib.ExitStack() as stack:
                cwd = stack.enter_context(checkout(against)) if on is None and against else None
                runs[name] = one_run(on, duration, ctx.device, ctx.say, cwd)
        except Exception as exc:  # one failed run still reports the others
            errors[name] = f"{type(exc).__name__}: {exc}"
            continue
        if runs[name]["problems"]:
            errors[name] = "; ".join(runs[name]["problems"])
    rows = [_row(name, r) for name, r in runs.items()]
    if len(runs) == 2:
        on, off = runs["on"], runs["off"]
        rows.append(
            {
                "run": "on / off",
                "RTF": _ratio(on["rtf"], off["rtf"]),
                "RTF/idle": _ratio(on["rtf_of_idle"], off["rtf_of_idle"]),
                "RTF min 1 s": _ratio(on["rtf_min"], off["rtf_min"]),
                "acked/s": _ratio(on["accepted_per_s"], off["accepted_per_s"]),
            }
        )
    notes = [
        f"{CLIENTS} clients × {RATE:g}/s on {WORLDS} worlds, {duration:g} s a run, engine "
        f"{ctx.device} default; load 1m is the box's load average at the run's start→end "
        "(a shared box: read each RTF beside it)",
        "RTF: ticks stepped over the load window / its wall time; the target is ≥ 0.95 with "
        "every accepted command acked in order (lost/dup/reordered 0/0/0). RTF idle: the same "
        f"service's first {IDLE_S:g} s with no commands; RTF/idle: what the commands cost the "
        "ticks, apart from what the box's other load costs them",
        "tick CPU ms idle: CPU the server and its engine workers spent per tick with no "
        f"commands (a 60 Hz tick has 16.7 ms of each of the box's {os.cpu_count()} cores); "
        "cores: CPU seconds per second under load (warm-up and drain included) of the "
        "server's process, its engine workers, the clients (this process), the rest of the "
        "box, and what was left idle; tick ms under load: the engine's step (wall), the "
        "loop's own work around it (GIL waits included), and the wall time from one tick to "
        "the next; command CPU ms: the server's CPU under load beyond its ticks at their idle "
        "cost per command answered, the clients' per command sent; cores needed: what 60 "
        f"ticks/s and {CLIENTS * RATE:,.0f} commands/s take at those costs (the box has "
        f"{os.cpu_count()})",
    ]
    return Result(rows, data={"runs": runs, "errors": errors}, notes=notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
