"""`armfleet capacity` end to end: the real command, quick, against real servers it starts.

Small batches and short windows (`--quick --worlds 8 --max-worlds 8`): what is checked is that
the command measures the limit, serves the engine in fast mode then in realtime mode, checks its
answer, and prints what it writes; never how fast anything is (the CI box is shared).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from bench.how_many import UNDER, _below


def test_capacity_prints_and_writes_the_same_answer(tmp_path: Path) -> None:
    out = tmp_path / "capacity.json"
    args = ["capacity", "--quick", "--engine", "mujoco", "--worlds", "8", "--max-worlds", "8"]
    proc = subprocess.run(
        [sys.executable, "-m", "service.cli", *args, "--check", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    text = proc.stdout
    result = json.loads(out.read_text())
    limit = result["limit"]
    assert limit["world_steps_per_s"] > 0 and limit["threads"] >= 1, limit
    assert limit["solver"] == "newton"  # the native engine's (physics.ENGINE_SOLVER)
    assert f"rollout limit: {limit['worlds']:,.0f} worlds at 60 Hz" in text, text
    assert result["machine"]["cpu_model"] in text
    assert list(result["engines"]) == ["mujoco"]
    native = result["engines"]["mujoco"]
    probe = native["fast"][0]
    assert probe["nworld"] == 8 and probe["ticks_per_s"] > 0
    runs = native["runs"]
    assert runs and all(r["nworld"] <= 8 for r in runs)
    assert all(r["held"] == (r["realtime_factor"] >= result["rtf_goal"]) for r in runs)
    held = [r["nworld"] for r in runs if r["held"]]
    assert native["worlds"] == (max(held) if held else None)
    if native["worlds"]:
        ratio = native["worlds"] / limit["worlds"]
        line = f"native MuJoCo (--engine mujoco): {native['worlds']:,} worlds in real time = "
        assert f"{line}{ratio:.2f}x the limit" in text, text
        check = native["check"]
        assert check["nworld"] == native["worlds"] and check["wall_s"] > 0
        assert f"checked: RTF {check['realtime_factor']:.3f}" in text, text
        assert proc.returncode == (0 if check["held"] else 1), proc.stderr
    else:  # a box too busy for even 8 worlds: said, and the exit status says so
        assert "none held" in text and proc.returncode == 1, text
    assert f"wrote {out}" in text
    # the table the docs show a result file by (bench.figures.section_table)
    assert [r["worlds"] for r in result["rows"]] == [round(limit["worlds"]), native["worlds"]]
    assert result["command"][1:3] == ["capacity", "--quick"]


def test_an_unknown_engine_is_refused_by_name() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "service.cli", "capacity", "--engine", "bullet"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert "engine: unknown ['bullet']" in proc.stderr and "mujoco, warp" in proc.stderr


def test_a_miss_always_steps_down() -> None:
    for n in (1, 2, 15, 16, 24, 1000):
        for rtf in (0.2, 0.98, 0.999, 1.2):
            nxt = _below(n, rtf)
            assert 1 <= nxt <= max(1, n - 1) and nxt <= max(1, n * min(rtf, 1.0) * UNDER + 1)
