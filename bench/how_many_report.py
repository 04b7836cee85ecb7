"""What `armfleet capacity` prints and the table its result file is shown by.

Apart from bench/how_many.py, which measures: this only reads the result dict.
"""

from __future__ import annotations

from typing import Any


def _held_run(res: dict[str, Any]) -> dict[str, Any] | None:
    """The realtime run that holds the engine's answer (None: none held)."""
    runs = res.get("runs", [])
    return next((r for r in runs if r["held"] and r["nworld"] == res.get("worlds")), None)


def _rows(limit: dict[str, Any], results: dict[str, Any]) -> list[dict[str, Any]]:
    """The table of the answer (bench.figures.section_table shows result files by it)."""
    rows: list[dict[str, Any]] = [
        {"what": "rollout limit", "worlds": round(limit["worlds"]), "× the limit": 1.0}
    ]
    for res in results.values():
        held = _held_run(res)
        beside = held.get("limit_worlds_beside") if held else None
        rows.append(
            {
                "what": res["label"],
                "worlds": res.get("worlds"),
                "× the limit": res.get("ratio_to_limit"),
                "× the limit beside": res["worlds"] / beside if beside else None,
                "RTF": held["realtime_factor"] if held else None,
                "check RTF": res["check"]["realtime_factor"] if res.get("check") else None,
            }
        )
    return rows


def report(result: dict[str, Any]) -> str:
    """The answer in words: the limit, then each engine's worlds and ratio to it."""
    m, limit = result["machine"], result["limit"]
    load = m.get("loadavg_at_start")
    lines = [
        f"{m['cpu_model']}, {m['usable_cores']} cores"
        + (f", {m['gpu']}" if m.get("gpu") else "")
        + (f" (load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f})" if load else ""),
        f"  rollout limit: {limit['worlds']:,.0f} worlds at 60 Hz (raw mujoco.rollout of the "
        f"served model, {limit['threads']} threads, {limit['solver']} solver; the best of "
        f"{len(limit['readings'])} blocks read through the run, spread {limit['spread']:.0%})",
    ]
    for res in result["engines"].values():
        if res.get("worlds"):
            line = (
                f"  {res['label']}: {res['worlds']:,} worlds in real time = "
                f"{res['ratio_to_limit']:.2f}x the limit"
            )
            beside = (_held_run(res) or {}).get("limit_worlds_beside")
            line += f" ({res['worlds'] / beside:.2f}x the block read before it)" if beside else ""
        else:
            line = f"  {res['label']}: none held" + (
                f" ({res['error']})" if res.get("error") else ""
            )
        if res.get("check"):
            c = res["check"]
            line += (
                f"; checked: RTF {c['realtime_factor']:.3f} over {c['wall_s']:.0f} s "
                f"({'held' if c['held'] else 'MISSED'})"
            )
        lines.append(line)
    lines.append(
        f"  (real time: RTF >= {result['rtf_goal']} with one 30 Hz subscriber of every world; "
        f"{result['seconds']:.0f} s)"
    )
    return "\n".join(lines)
