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

from bench.how_many_sizes import MAX_RUNS, UNDER, _below, capped, next_size


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
    assert result["servers_start"].startswith("realtime")  # as `armfleet serve` starts


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


def test_the_search_brackets_the_answer_and_ends() -> None:
    """`next_size` from any run: a miss goes down, a hold with room goes up, never outside
    the bracket of what held and what missed, and every search ends within MAX_RUNS."""
    miss = {"held": False, "realtime_factor": 0.9}
    assert next_size(400, miss, None, 400) == _below(400, 0.9) < 400
    roomy = {"held": True, "realtime_factor": 1.0, "tick_share": 0.7}
    assert 400 < next_size(400, roomy, 400, None) <= 400 / 0.7
    assert next_size(400, roomy, 400, 424) is None  # the middle is within reach of 400
    assert next_size(400, {"held": True, "tick_share": 0.95}, 400, None) is None  # no room
    # a miss just above what held: the middle of the bracket, or done when that is close
    assert next_size(480, {"held": False, "realtime_factor": 0.98}, 400, 480) == 456
    assert next_size(480, {"held": False, "realtime_factor": 0.8}, 400, 480) == 440
    assert next_size(416, {"held": False, "realtime_factor": 0.99}, 400, 416) is None
    # a step up never passes what fast mode predicted, nor --max-worlds
    assert capped(480, 400, 440, None) == 440 and capped(300, 400, 440, None) == 300
    assert capped(410, 400, 440, None) is None and capped(480, 400, 500, 410) is None
    for rtf in (0.3, 0.9, 0.985):
        for share in (0.3, 0.8):
            n, lo, hi, runs = 400, None, None, 1
            while True:
                held = n * 0.9 <= 400 * share / 0.8 * rtf  # a machine holding a fixed size
                res = {"held": held, "realtime_factor": 1.0 if held else rtf, "tick_share": share}
                lo, hi = (max(lo or 0, n), hi) if held else (lo, min(hi or n, n))
                nxt = next_size(n, res, lo, hi)
                if nxt is None or runs == MAX_RUNS:
                    break
                assert (lo is None or nxt > lo) and (hi is None or nxt < hi), (n, lo, hi, nxt)
                n, runs = nxt, runs + 1
