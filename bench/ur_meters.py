"""What bench section 32 (bench/ur_programs.py) reads off the service during a run: the
ticks each second with the CPU the service used (`RtfSampler`), and the UR thread's CPU per
RTDE package with the ticks' gaps as the sim thread saw them (`UrThread`, GET /v1/ur).
A module of its own so that the section's module keeps to the runs and their report."""

from __future__ import annotations

import threading
import time
from typing import Any

import httpx
import psutil

from bench import common


def _cpu(proc: psutil.Process) -> float:
    """CPU seconds of a process and its children so far (the service's engine workers)."""
    t = proc.cpu_times()
    return t.user + t.system + t.children_user + t.children_system


class RtfSampler:
    """The service's ticks sampled every second (/v1/info) in a thread: each 1 s window's RTF;
    and the CPU the service and this process used over the whole window."""

    def __init__(self, srv: common.Served) -> None:
        self.proc = psutil.Process(srv.server.process.pid)
        self.cpu0, self.own0 = _cpu(self.proc), time.process_time()
        self.srv, self.samples = srv, [srv.get_info()]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(1.0):
            try:
                self.samples.append(self.srv.get_info())
            except httpx.HTTPError:
                continue

    def stop(self) -> dict[str, Any]:
        self._stop.set()
        self._thread.join()
        self.samples.append(self.srv.get_info())
        pairs = list(zip(self.samples, self.samples[1:], strict=False))
        per_s = [common.rtf_between(a, b) for a, b in pairs if b[0] - a[0] > 0.5]
        wall = self.samples[-1][0] - self.samples[0][0]
        return {
            "service_cpu": round((_cpu(self.proc) - self.cpu0) / wall, 3),  # cores busy
            "bench_cpu": round((time.process_time() - self.own0) / wall, 3),
            "rtf": round(common.rtf_between(self.samples[0], self.samples[-1]), 3),
            "rtf_min_1s": round(min(per_s), 3) if per_s else None,
            "ticks": self.samples[-1][1]["tick"] - self.samples[0][1]["tick"],
            "seconds": round(self.samples[-1][0] - self.samples[0][0], 2),
        }


class UrThread:
    """What the service's UR thread did over a run (GET /v1/ur before and after): its CPU
    per RTDE package sent (all its work: the sends, the packing, the inputs and commands),
    and the ticks' gaps while RTDE streamed as the sim thread saw them (the longest since the
    service started: before the programs nothing streams)."""

    def __init__(self, srv: common.Served) -> None:
        self.srv = srv
        self.before = self._read()

    def _read(self) -> dict[str, Any]:
        return httpx.get(f"{self.srv.url}/v1/ur", timeout=30).json()

    def stop(self) -> dict[str, Any]:
        a, b = self.before, self._read()
        if a.get("thread_cpu_s") is None or b.get("thread_cpu_s") is None:
            return {}
        cpu = b["thread_cpu_s"] - a["thread_cpu_s"]
        sent = b["rtde_packages_sent"] - a["rtde_packages_sent"]
        gaps = b.get("tick_gaps") or {}
        return {
            "ur_thread_cpu_s": round(cpu, 3),
            "rtde_packages_sent": sent,
            "ur_thread_us_per_package": round(cpu / sent * 1e6, 1) if sent else None,
            "tick_gap_longest_ms": round(gaps.get("longest_s", 0.0) * 1e3, 1),
            "tick_gaps_over_100ms": gaps.get("over_100ms", 0)
            - (a.get("tick_gaps") or {}).get("over_100ms", 0),
        }
