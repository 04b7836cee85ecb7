"""Where a parallel run's time went, file by file (registered by tests/conftest.py).

`scripts/dev.py test` hands whole files to pytest-xdist workers, longest first
(conftest.LONGEST_FIRST), so that no long file starts late and keeps one worker busy while the
others idle. Whether that holds can only be seen in a whole run: this prints, at the end of one
with workers, the files that took longest (from their first test's start to their last test's
end, as the controller saw the reports arrive), the worker each ran on and when it started and
ended, and when each worker finished its last file. A file that ends near the run's end and
started late is the one to move up LONGEST_FIRST.
"""

from __future__ import annotations

import resource
import time
from dataclasses import dataclass, field
from typing import Any

import pytest

SHOWN = 15  # files listed
CPU_KEY = "armfleet_cpu_s"


def _cpu_seconds() -> float:
    """This process's CPU time plus that of its children that have been waited for."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


@dataclass
class FileTimes:
    worker: str
    start: float  # seconds since the session started
    end: float
    tests: set[str] = field(default_factory=set)
    cpu: float = 0.0


class WorkerCpu:
    """A pytest plugin for an xdist worker: the CPU spent since its previous report, on each."""

    def __init__(self) -> None:
        self.last = _cpu_seconds()

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: Any) -> Any:
        outcome = yield
        now = _cpu_seconds()
        outcome.get_result().user_properties.append((CPU_KEY, now - self.last))
        self.last = now


class SuiteTimes:
    """A pytest plugin for the xdist controller: each report's arrival, by file."""

    def __init__(self) -> None:
        self.t0 = time.monotonic()
        self.files: dict[str, FileTimes] = {}

    @pytest.hookimpl
    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        node = getattr(report, "node", None)  # set by xdist on the controller
        if node is None:
            return
        now = time.monotonic() - self.t0
        worker = str(getattr(node, "gateway", node).id)
        path = report.nodeid.split("::", 1)[0]
        times = self.files.get(path)
        if times is None:
            start = now - report.duration  # the report comes once its phase is done
            times = self.files[path] = FileTimes(worker, start, now)
        times.end = max(times.end, now)
        times.tests.add(report.nodeid)
        times.cpu += sum(v for k, v in report.user_properties if k == CPU_KEY)

    @pytest.hookimpl
    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        if not self.files:
            return
        write = terminalreporter.write_line
        terminalreporter.section("files by wall time (scripts/dev.py test's schedule)")
        ranked = sorted(self.files.items(), key=lambda kv: kv[1].start - kv[1].end)
        write(f"{'wall s':>7} {'cpu s':>7} {'start':>7} {'end':>7}  worker  tests  file")
        for path, t in ranked[:SHOWN]:
            write(
                f"{t.end - t.start:7.1f} {t.cpu:7.1f} {t.start:7.1f} {t.end:7.1f}  {t.worker:6}"
                f"  {len(t.tests):5}  {path}"
            )
        total = sum(t.cpu for t in self.files.values())
        write(f"CPU by file (workers and the processes they reaped; all files: {total:.0f} s):")
        by_cpu = sorted(self.files.items(), key=lambda kv: -kv[1].cpu)
        write("  " + ", ".join(f"{p.removeprefix('tests/')} {t.cpu:.0f}" for p, t in by_cpu[:30]))
        last: dict[str, tuple[float, str]] = {}
        for path, t in self.files.items():
            if t.end > last.get(t.worker, (-1.0, ""))[0]:
                last[t.worker] = (t.end, path)
        ends = ", ".join(f"{w} at {e:.0f} s ({p})" for w, (e, p) in sorted(last.items()))
        write(f"each worker's last file ended: {ends}")


def pytest_configure(config: pytest.Config) -> None:
    """Only the controller of a run with workers reports (a worker, or a run without
    xdist, has no schedule to show)."""
    if hasattr(config, "workerinput"):
        config.pluginmanager.register(WorkerCpu(), "armfleet-worker-cpu")
        return
    workers = getattr(config.option, "numprocesses", None)
    if workers:
        config.pluginmanager.register(SuiteTimes(), "armfleet-suite-times")
