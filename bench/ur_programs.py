"""UR programs at scale: 32 ur_rtde programs at once, and RTDE at 500 Hz to 32 clients at once,
against one `armfleet serve --worlds 32 --ur`.

Issue 40's targets: "32 worlds, each driven by its own ur_rtde program at once (control and
receive), in real time on the 2-core box; RTDE receive at 500 Hz to 32 clients at once, the
delivered rate and the ticks held". Two runs on the same service, one after the other:

* **programs**: 32 processes (forked), each the registry's ur-rtde 1.6.5 wheel unchanged on its
  world's address (`RTDEControlInterface` + `RTDEReceiveInterface`, their default 500 Hz
  streams: 64 streams in all), each connecting, waiting for the others, then moveJ, two moveL,
  ten command round trips (getForwardKinematics, isSteady), 150 reads and moveJ back
  (bench/ur_clients.py). Reported: every program's success, connect time, each call's
  duration (a move's includes its motion; a command round trip is the register handshake
  through the service's next RTDE packages), and the ticks' RTF over the programs' window
  (ticks stepped / wall time) and its lowest 1 s sample.
* **receive**: 32 raw RTDE clients (one each world, in this process: ur_rtde has no package
  count, see bench/ur_clients.py) with one output recipe at 500 Hz: the packages delivered
  per second per client (min / median / max over the clients), the longest silence a client
  saw, and the ticks' RTF meanwhile.

The box's load (`uptime`'s 1 min average) is recorded at each run's start and end: on a shared
machine read every figure beside it. The engine is native MuJoCo on `--device cpu` (the cost
measured is the UR surface's; the engines' own real-time capacity is section 11's), MuJoCo
Warp on a CUDA device; ARMFLEET_UR_BENCH_ENGINE overrides it. --worlds N runs N programs and
N receivers on N worlds. ARMFLEET_UR_BENCH_SECONDS sets the receive window (default 20; 8
with --quick).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import random
import statistics
import threading
import time
from typing import Any

import httpx

from bench import common, ur_clients
from bench.registry import Context, Result, section
from bench.ur_meters import RtfSampler, UrThread

ENGINE_ENV = "ARMFLEET_UR_BENCH_ENGINE"
SECONDS_ENV = "ARMFLEET_UR_BENCH_SECONDS"
RECEIVE_HZ = 500.0
# A program's deadline from the start: it takes seconds (20-40 s under others' load); a program
# past it is ended and counted as failed, so that one stuck ur_rtde never holds the run.
PROGRAM_DEADLINE_S = 180.0


def _engine(device: str) -> str:
    return os.environ.get(ENGINE_ENV) or ("mujoco" if device == "cpu" else "warp")


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _ms(values: list[float], q: float) -> float | None:
    p = common.percentile(values, q)
    return None if p is None else round(p * 1e3, 4)


def _gap_ms(gap_s: float | None) -> float | None:
    return None if gap_s is None else round(gap_s * 1e3, 1)


def _collect(out: Any, procs: list[Any], limit_s: float = 600.0) -> list[dict[str, Any]]:
    """Every program's result within `limit_s`; a program still running then is ended (its
    process killed) and recorded as failed; one whose process died without a result is left
    out (run_programs records it)."""
    import queue

    results: list[dict[str, Any]] = []
    end = time.monotonic() + limit_s
    while len(results) < len(procs) and time.monotonic() < end:
        try:
            results.append(out.get(timeout=1.0))
        except queue.Empty:
            if not any(p.is_alive() for p in procs) and out.empty():
                break
    got = {r["world"] for r in results}
    for world, p in enumerate(procs):
        if world not in got and p.is_alive():
            p.kill()
            p.join(timeout=5)
            results.append(
                {"world": world, "ok": False, "calls": {}, "error": f"no result in {limit_s:g} s"}
            )
    return results


def run_programs(srv: common.Served, addresses: list[str], say: Any) -> dict[str, Any]:
    """One ur_rtde program per address, each in a forked process, started together."""
    ctx = mp.get_context("fork")  # 32 interpreters without 32 imports of the bench
    n = len(addresses)
    barrier, out = ctx.Barrier(n + 1), ctx.Queue()
    procs = [
        ctx.Process(target=ur_clients.program, args=(a, w, barrier, out), daemon=True)
        for w, a in enumerate(addresses)
    ]
    t_connect = time.perf_counter()
    for p in procs:
        p.start()
    load = _load()
    try:
        barrier.wait(timeout=300)  # every program connected (or failed to)
    except threading.BrokenBarrierError:  # one hung connecting: _collect ends it
        say("    not every program connected in 300 s; the others run")
    connected_s = time.perf_counter() - t_connect
    say(f"    {n} programs connected in {connected_s:.1f} s (load {load}); running")
    sampler, ur_thread = RtfSampler(srv), UrThread(srv)
    results = _collect(out, procs, PROGRAM_DEADLINE_S)
    ticks = sampler.stop()
    ur = ur_thread.stop()
    for p in procs:
        p.join(timeout=30)
    gaps = {  # the longest each world's RTDE clients went without a package, server-side
        w["world"]: w.get("rtde_longest_gap_s")
        for w in httpx.get(f"{srv.url}/v1/ur", timeout=30).json()["worlds"]
    }
    lost = sorted(set(range(n)) - {r["world"] for r in results})
    results += [{"world": w, "ok": False, "error": "the process died", "calls": {}} for w in lost]
    results.sort(key=lambda r: r["world"])
    calls = {k: [x for r in results for x in r["calls"].get(k, [])] for k in ur_clients.CALLS}
    per_program = [
        {
            "world": r["world"],
            "ok": r["ok"],
            "error": r["error"] or ("; ".join(r.get("failed", [])) or None),
            "cleanup": r.get("cleanup"),  # stopScript and disconnects: "done", or what hung
            "ur_rtde_printed": r.get("ur_rtde_printed"),  # a failed program's last lines
            "connect_s": round(r.get("connect_s", 0.0), 3),
            "run_s": round(r.get("run_s", 0.0), 3),
            "run_cpu_s": round(r.get("run_cpu_s", 0.0), 3),
            "moveL_error_mm": round(r["moveL_error_m"] * 1e3, 3) if "moveL_error_m" in r else None,
            "server_gap_ms": _gap_ms(gaps.get(r["world"])),
            "moveJ_ms": [round(x * 1e3, 1) for x in r["calls"].get("moveJ", [])],
            "moveL_ms": [round(x * 1e3, 1) for x in r["calls"].get("moveL", [])],
            **{
                f"{k}_p50_max_ms": [_ms(r["calls"].get(k, []), 50), _ms(r["calls"].get(k, []), 100)]
                for k in ("command", "read")
            },
        }
        for r in results
    ]
    wall = ticks["seconds"]
    cpu = sum(r.get("run_cpu_s", 0.0) for r in results)
    return {
        "programs": n,
        "programs_cpu": round(cpu / wall, 3) if wall else None,  # cores busy, all programs
        "ok": sum(r["ok"] for r in results),
        "connect_all_s": round(connected_s, 2),
        "load_1m_at_start": load,
        "load_1m_at_end": _load(),
        **ticks,
        **ur,
        "latency_ms": {
            k: {"p50": _ms(v, 50), "p99": _ms(v, 99), "max": _ms(v, 100), "n": len(v)}
            for k, v in calls.items()
        },
        "connect_s_max": max((r.get("connect_s", 0.0) for r in results), default=None),
        "server_gap_max_ms": _gap_ms(max((g for g in gaps.values() if g), default=None)),
        "per_program": per_program,
    }


def run_receivers(srv: common.Served, addresses: list[str], window_s: float) -> dict[str, Any]:
    """One raw 500 Hz receiver per address, all in this process, counted over `window_s`."""
    load = _load()
    sampler: list[Any] = []
    box = ur_clients.receive(
        addresses,
        RECEIVE_HZ,
        2.0,
        window_s,
        at_start=lambda: sampler.extend((RtfSampler(srv), UrThread(srv))),
    )
    ticks = sampler[0].stop()
    ur = sampler[1].stop()
    rxs = box["receivers"]
    t0, t1 = box["window"]
    rates = [rx.packages / (t1 - t0) for rx in rxs if rx.error is None]
    return {
        "clients": len(rxs),
        "frequency_hz": RECEIVE_HZ,
        "window_s": round(t1 - t0, 2),
        "package_bytes": rxs[0].size if rxs else None,
        "load_1m_at_start": load,
        "load_1m_at_end": _load(),
        **ticks,
        **{k: v for k, v in ur.items() if k != "tick_gap_longest_ms"},  # since the start
        "rate_min": round(min(rates), 1) if rates else None,
        "rate_median": round(statistics.median(rates), 1) if rates else None,
        "rate_max": round(max(rates), 1) if rates else None,
        "max_silence_ms": round(max((rx.max_gap_s for rx in rxs), default=0.0) * 1e3, 1),
        "errors": {rx.address: rx.error for rx in rxs if rx.error},
        "per_client": [
            {
                "address": rx.address,
                "rate": round(rx.packages / (t1 - t0), 1),
                "max_silence_ms": round(rx.max_gap_s * 1e3, 1),
                "error": rx.error,
            }
            for rx in rxs
        ],
    }


def _addresses(srv: common.Served) -> list[str]:
    ur = httpx.get(f"{srv.url}/v1/ur", timeout=30).json()
    return [w["address"] for w in sorted(ur["worlds"], key=lambda w: w["world"])]


def _engine_priority(srv: common.Served) -> str:
    """What the threads that step the worlds and the UR thread ran at (GET /v1/ur;
    `--engine-priority`, which ARMFLEET_ENGINE_PRIORITY sets for the bench's service too)."""
    ur = httpx.get(f"{srv.url}/v1/ur", timeout=30).json()
    p = ur.get("engine_priority") or {}
    nice = [t["nice"] for t in p.get("threads", [])]
    return (
        f"{p.get('setting')}: nice {nice}, UR thread {ur.get('thread_nice')} "
        f"(process {p.get('process_nice')})"
    )


def _rows(n: int, prog: dict[str, Any], recv: dict[str, Any]) -> list[dict[str, Any]]:
    """One row a run; latencies as p50/p99."""
    lat = prog.get("latency_ms", {})

    def p(k: str, scale: float = 1.0, digits: int = 0) -> str:
        d = lat.get(k) or {}
        if d.get("p50") is None:
            return "-"
        return f"{d['p50'] * scale:.{digits}f}/{d['p99'] * scale:.{digits}f}"

    rows = []
    if prog:
        rows.append(
            {
                "run": f"{n} programs",
                "load 1m": f"{prog['load_1m_at_start']:.1f}→{prog['load_1m_at_end']:.1f}",
                "ok": f"{prog['ok']}/{prog['programs']}",
                "RTF": prog["rtf"],
                "RTF min 1 s": prog["rtf_min_1s"],
                "moveJ ms": p("moveJ"),
                "moveL ms": p("moveL"),
                "command ms": p("command", digits=1),
                "read µs": p("read", 1e3),
                "connect s": round(prog["connect_s_max"] or 0.0, 2),
                "tick gap ms": prog.get("tick_gap_longest_ms", "-"),
                "UR µs/pkg": prog.get("ur_thread_us_per_package", "-"),
                "CPU service/clients": f"{prog['service_cpu']:.2f}/{prog['programs_cpu']:.2f}",
            }
        )
    if recv:
        rows.append(
            {
                "run": f"{recv['clients']} × {recv['frequency_hz']:g} Hz",
                "load 1m": f"{recv['load_1m_at_start']:.1f}→{recv['load_1m_at_end']:.1f}",
                "ok": f"{recv['clients'] - len(recv['errors'])}/{recv['clients']}",
                "RTF": recv["rtf"],
                "RTF min 1 s": recv["rtf_min_1s"],
                "Hz min/median": f"{recv['rate_min']:.0f}/{recv['rate_median']:.0f}",
                "silence ms": recv["max_silence_ms"],
                "UR µs/pkg": recv.get("ur_thread_us_per_package", "-"),
                "CPU service/clients": f"{recv['service_cpu']:.2f}/{recv['bench_cpu']:.2f}",
            }
        )
    return rows


@section(32, "ur_programs", devices=("cpu", "cuda"), default_on=())
def ur_programs(ctx: Context) -> Result:
    """UR programs: 32 ur_rtde programs at once, RTDE at 500 Hz to 32 clients

    Both runs on one `--ur` service of `--worlds` worlds (default 32)."""
    n = ctx.sizes((32,))[0]
    engine = _engine(ctx.device)
    window = float(os.environ.get(SECONDS_ENV) or ctx.pick(20.0, 8.0))
    a, b = random.randrange(2, 250), random.randrange(0, 250)  # a block no one else serves
    env = {
        "ARMFLEET_UR": "true",
        "ARMFLEET_UR_ADDRESSES": f"127.{a}.{b}.1-127.{a}.{b}.{n}",
        "ARMFLEET_ENGINE": engine,
    }
    errors: dict[str, str] = {}
    prog: dict[str, Any] = {}
    recv: dict[str, Any] = {}
    with ctx.serve(n, "realtime", env=env) as srv:
        addresses = _addresses(srv)
        idle = RtfSampler(srv)
        time.sleep(3.0)
        idle_ticks = idle.stop()
        priority = _engine_priority(srv)
        ctx.say(
            f"  {n} worlds ({engine}), idle RTF {idle_ticks['rtf']} (load {_load()}); "
            f"engine priority {priority}"
        )
        try:
            prog = run_programs(srv, addresses, ctx.say)
            ctx.say(f"  programs: {prog['ok']}/{n} ok, RTF {prog['rtf']}")
        except Exception as exc:
            errors["programs"] = f"{type(exc).__name__}: {exc}"
        failed = [p for p in prog.get("per_program", []) if not p["ok"]]
        if failed:
            errors["programs"] = f"{len(failed)} failed, e.g. world {failed[0]['world']}: " + str(
                failed[0]["error"]
            )
        try:
            recv = run_receivers(srv, addresses, window)
            ctx.say(f"  receive: median {recv['rate_median']} Hz, RTF {recv['rtf']}")
        except Exception as exc:
            errors["receive"] = f"{type(exc).__name__}: {exc}"
        if recv.get("errors"):
            errors["receive"] = f"{len(recv['errors'])} receivers failed: " + str(
                next(iter(recv["errors"].values()))
            )
    notes = [
        f"{n} worlds, engine {engine} on {ctx.device}, 60 Hz ticks, realtime; idle (3 s before "
        f"the runs): RTF {idle_ticks['rtf']}, service CPU {idle_ticks['service_cpu']}; engine "
        f"priority {priority} (the sim thread first); load 1m: "
        "the box's load average at the run's start→end (a shared box: read each figure beside it)",
        "programs: the registry's ur-rtde 1.6.5, RTDEControlInterface + RTDEReceiveInterface "
        "(default 500 Hz each) per world, one process each; p50/p99 over all programs' calls: "
        "moveJ/moveL include the motion; command = a getForwardKinematics or isSteady round "
        "trip through the registers; read = a receive getter; connect = the slowest program's "
        "two constructors; server gap = the longest a world's RTDE clients went without a "
        "package, as the service counts it (GET /v1/ur; ur_rtde drops a connection at 2.5 s: "
        "a program that died with a short server gap had its own process starved)",
        "tick gap = the longest time between two ticks while RTDE streamed, as the "
        "service's sim thread saw it (GET /v1/ur tick_gaps; tick_gaps_over_100ms counts "
        "those of 0.1 s or more); UR µs/pkg = the UR thread's CPU over the run (all its work: "
        "sends, packing, inputs, commands) per RTDE data package it sent",
        "receivers: raw RTDE clients (ur_rtde has no package count), one 500 Hz output recipe "
        f"of {recv.get('package_bytes')} bytes each, all in the bench's process; Hz = packages "
        "delivered per second per client (min/median over clients); silence = the longest "
        "time a client got nothing; RTF over the counting window",
    ]
    data = {
        "worlds": n,
        "engine": engine,
        "engine_priority": priority,
        "idle": idle_ticks,
        "programs": prog,
        "receive": recv,
        "errors": errors,
    }
    return Result(_rows(n, prog, recv), data=data, notes=notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
