"""Summarise timeline JSON files (tlpatch.py): medians and means per stage, microseconds."""

import json
import statistics
import sys


def us(xs):
    xs = [x for x in xs if x is not None]
    if not xs:
        return "-"
    return f"mean {statistics.fmean(xs):7.1f}  p50 {statistics.median(xs):7.1f}  p90 {sorted(xs)[int(len(xs) * 0.9)]:7.1f}"


def main(path):
    d = json.load(open(path))
    t = [x for x in d["ticks"] if "synced" in x and "next_start" in x]
    print(f"== {path} ({d['where']}, {len(t)} ticks)")
    wall = [(x["next_start"] - x["start"]) / 1e3 for x in t]
    print(f"tick wall (start->next start)      {us(wall)}")
    print(f"device graph ms*1000               {us([x['dev_graph_ms'] * 1e3 for x in t])}")
    print(f"device idle gap                    {us([x.get('dev_gap_ms', 0) * 1e3 for x in t[1:]])}")
    print(f"start -> launch (before graph)     {us([(x['launch'] - x['start']) / 1e3 for x in t])}")
    print(
        f"launch call                        {us([(x['launched'] - x['launch']) / 1e3 for x in t])}"
    )
    print(
        f"launched -> synced (wait)          {us([(x['synced'] - x['launched']) / 1e3 for x in t])}"
    )
    print(f"synced -> end of tick_once         {us([(x['end'] - x['synced']) / 1e3 for x in t])}")
    print(
        f"end -> next start (_run)           {us([(x['next_start'] - x['end']) / 1e3 for x in t])}"
    )
    host = []
    for a, b in zip(t, t[1:]):
        host.append((b["launch"] - a["synced"]) / 1e3)
    print(f"synced -> next launch (host)       {us(host)}")
    gaps = [b.get("dev_gap_ms", 0) * 1e3 - h for b, h in zip(t[1:], host)]
    print(f"dev gap - host (wake/GIL/launch)   {us(gaps)}")
    keys = sorted(
        {k for x in t for k in x}
        - {
            "start",
            "end",
            "launch",
            "launched",
            "synced",
            "next_start",
            "dev_gap_ms",
            "dev_graph_ms",
        }
    )
    for k in keys:
        vals = [x.get(k, 0) / 1e3 for x in t]
        n = sum(1 for x in t if k in x)
        print(
            f"  {k:<28} per tick {statistics.fmean(vals):7.1f} us  (in {n} ticks; when there p50 {statistics.median([v for v in vals if v] or [0]):7.1f})"
        )
    secs = (t[-1]["next_start"] - t[0]["start"]) / 1e9
    print(
        f"thread CPU over {secs:.1f} s:",
        {k: round(v, 2) for k, v in d["thread_cpu_s"].items() if v > 0.005},
    )


for p in sys.argv[1:]:
    main(p)
