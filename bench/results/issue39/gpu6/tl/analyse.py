"""Summarise timeline files (tlpatch.py): means and quantiles per stage, microseconds."""

import gzip
import itertools
import json
import statistics
import sys

STAMPS = {"start", "end", "launch", "launched", "synced", "next_start"}
DEVICE = {"dev_gap_ms", "dev_graph_ms"}


def us(xs: list[float]) -> str:
    if not xs:
        return "-"
    p50, p90 = statistics.median(xs), sorted(xs)[int(len(xs) * 0.9)]
    return f"mean {statistics.fmean(xs):7.1f}  p50 {p50:7.1f}  p90 {p90:7.1f}"


def span(t: list[dict], a: str, b: str) -> list[float]:
    return [(x[b] - x[a]) / 1e3 for x in t]


def main(path: str) -> None:
    with (gzip.open if path.endswith(".gz") else open)(path, "rt") as f:
        d = json.load(f)
    t = [x for x in d["ticks"] if "synced" in x and "next_start" in x]
    print(f"== {path} ({d['where']}, {len(t)} ticks)")
    print(f"tick wall (start->next start)      {us(span(t, 'start', 'next_start'))}")
    print(f"device graph                       {us([x['dev_graph_ms'] * 1e3 for x in t])}")
    print(f"device idle gap                    {us([x.get('dev_gap_ms', 0) * 1e3 for x in t[1:]])}")
    print(f"start -> launch (before graph)     {us(span(t, 'start', 'launch'))}")
    print(f"launch call                        {us(span(t, 'launch', 'launched'))}")
    print(f"launched -> synced (wait)          {us(span(t, 'launched', 'synced'))}")
    print(f"synced -> end of tick_once         {us(span(t, 'synced', 'end'))}")
    print(f"end -> next start (_run)           {us(span(t, 'end', 'next_start'))}")
    host = [(b["launch"] - a["synced"]) / 1e3 for a, b in itertools.pairwise(t)]
    print(f"synced -> next launch (host)       {us(host)}")
    gaps = [b.get("dev_gap_ms", 0) * 1e3 - h for b, h in zip(t[1:], host, strict=True)]
    print(f"dev gap - host (wake/GIL/launch)   {us(gaps)}")
    for k in sorted({k for x in t for k in x} - STAMPS - DEVICE):
        vals = [x.get(k, 0) / 1e3 for x in t]
        there = [v for v in vals if v] or [0.0]
        print(
            f"  {k:<28} per tick {statistics.fmean(vals):7.1f} us  (in {len(there)} ticks; "
            f"when there p50 {statistics.median(there):7.1f})"
        )
    secs = (t[-1]["next_start"] - t[0]["start"]) / 1e9
    cpu = {k: round(v, 2) for k, v in d["thread_cpu_s"].items() if v > 0.005}
    print(f"thread CPU over {secs:.1f} s:", cpu)


if __name__ == "__main__":
    for p in sys.argv[1:]:
        main(p)
