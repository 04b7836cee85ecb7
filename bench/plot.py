"""Plot sections 1 and 2: world-steps/s against worlds, log-log → bench/results/throughput.png.

Standalone: ``python -m bench.plot`` redraws from bench/results/{throughput,service_fast}.json
(``--device cuda`` from the ``_cuda`` files).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bench import common

STYLE = {
    "engine": {"color": "tab:blue", "marker": "o", "lw": 2.2},
    "engine_cores": {"color": "tab:purple", "marker": "o", "lw": 2.2},
    "warp_captured": {"color": "tab:cyan", "marker": "s", "ls": "--"},
    "warp_python": {"color": "tab:gray", "marker": "v", "ls": ":"},
    "rollout_1t": {"color": "tab:orange", "marker": "^", "ls": "-."},
    "rollout_all": {"color": "tab:red", "marker": "D", "ls": "-."},
    "service": {"color": "tab:green", "marker": "*", "lw": 2.2, "ms": 10},
}
LABELS = {
    "engine": "armfleet engine (captured tick)",
    "engine_cores": "armfleet engine, worlds sharded over all cores",
    "warp_captured": "MuJoCo Warp, captured",
    "warp_python": "MuJoCo Warp, mjw.step from Python",
    "rollout_1t": "MuJoCo rollout, 1 thread",
    "rollout_all": "MuJoCo rollout, {n} threads",
    "service": "service, fast mode, 30 Hz stream",
}


def plot(
    throughput: dict[str, Any] | None,
    service: dict[str, Any] | None,
    path: Path,
    realtime_capacity: int | None = None,
) -> Path | None:
    """Draw what there is; returns the file written, None when there was nothing to draw."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series: dict[str, tuple[list[int], list[float]]] = {}
    if throughput:
        for n, entry in throughput.get("results", {}).items():
            for name, res in entry.get("engines", {}).items():
                xs, ys = series.setdefault(name, ([], []))
                xs.append(int(n))
                ys.append(res["world_steps_per_s"])
    if service:
        for n, res in service.get("results", {}).items():
            xs, ys = series.setdefault("service", ([], []))
            xs.append(int(n))
            ys.append(res["world_steps_per_s"])
    if not series:
        return None

    device = (throughput or service or {}).get("device", "cpu")
    machine = (throughput or service or {}).get("machine", {})
    nthread = (throughput or {}).get("rollout_threads", "?")
    fig, ax = plt.subplots(figsize=(11, 5.5), dpi=120)
    for name in (*STYLE, *[k for k in series if k not in STYLE]):
        if name not in series:
            continue
        xs, ys = series[name]
        order = sorted(range(len(xs)), key=xs.__getitem__)
        style = {"lw": 1.5, "ms": 6, **STYLE.get(name, {})}
        ax.plot(
            [xs[i] for i in order],
            [ys[i] for i in order],
            label=LABELS.get(name, name).format(n=nthread),
            **style,
        )
    # What real time needs: every world advancing control_hz * substeps physics steps a second.
    steps = 60 * (throughput or {}).get("substeps", 8)
    xs_all = sorted({x for xs, _ in series.values() for x in xs})
    ax.plot(
        xs_all,
        [x * steps for x in xs_all],
        color="black",
        lw=0.8,
        ls=(0, (1, 3)),
        label=f"real time ({steps} steps/s per world)",
    )
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    if realtime_capacity:
        ax.axvline(realtime_capacity, color="tab:green", lw=0.8, ls="--")
        ax.text(
            realtime_capacity,
            0.02,
            f" realtime capacity: {realtime_capacity} worlds",
            transform=ax.get_xaxis_transform(),  # x in data, y in axes fraction
            fontsize=8,
            color="tab:green",
        )
    ax.set_xlabel("worlds (nworld)")
    ax.set_ylabel("world-steps per second")
    title = f"Throughput on {device}: {machine.get('gpu') or machine.get('cpu_model', '')}"
    cores = machine.get("usable_cores")
    ax.set_title(title + (f", {cores} cores" if cores else ""), fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_xticks(xs_all, [str(x) for x in xs_all])
    ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def redraw(out_dir: Path, device: str = "cpu") -> Path | None:
    """throughput[_cuda].png from the result files of sections 1, 2 and 3 in `out_dir`."""
    suffix = common.suffix_for(device)
    cap = common.read_json(f"realtime_capacity{suffix}.json", out_dir) or {}
    return plot(
        common.read_json(f"throughput{suffix}.json", out_dir),
        common.read_json(f"service_fast{suffix}.json", out_dir),
        out_dir / f"throughput{suffix}.png",
        cap.get("capacity_worlds"),
    )


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.plot", description=__doc__)
    p.add_argument("--device", default="cpu", help="which result files: cpu or cuda")
    path = redraw(common.RESULTS_DIR, p.parse_args(argv).device)
    print(f"wrote {path}" if path else "nothing to plot: run sections 1 and 2 first")
    return 0 if path else 1


if __name__ == "__main__":
    raise SystemExit(main())
