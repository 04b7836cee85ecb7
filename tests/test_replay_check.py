"""How replay judges states (bit for bit or within a stated tolerance, deviation per tick range),
and the CUDA replay bench's Warp helpers (deterministic-mode fallback, the prebuild walk).

The end-to-end replays (CPU, bit-exact, over the API) are in test_recording.py; the CUDA figures
come from `python -m bench.replay_cuda` on a GPU (bench/results/replay_cuda.json).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import ROOT

from service.persistence.replay_check import (
    Comparison,
    Tolerance,
    bit_exact,
    format_table,
    table_span,
)

NAMES = [f"j{i}" for i in range(7)]


def state(value: float) -> np.ndarray:
    """One world's (position, velocity, effort) rows, all `value`."""
    return np.full((3, 7), value, dtype=np.float64)


def check(c: Comparison, tick: int, world: int, recorded: np.ndarray, replayed: np.ndarray):
    c.check(tick, np.array([world]), recorded[None], replayed[None])


def test_bit_for_bit_names_the_first_difference_and_keeps_counting():
    c = Comparison(NAMES, None, span=10)
    check(c, 1, 0, state(0.5), state(0.5))
    got = state(0.5)
    got[1][3] = np.nextafter(0.5, 1.0)  # one ulp of velocity
    check(c, 12, 2, state(0.5), got)
    check(c, 25, 2, state(0.5), state(0.75))
    d = c.divergence
    assert (d.tick, d.world, d.joint, d.quantity) == (12, 2, "j3", "velocity")
    rows = c.rows()
    assert [(r.first, r.last, r.states) for r in rows] == [(1, 1, 1), (11, 12, 1), (21, 25, 1)]
    assert rows[0].largest == {"position": 0.0, "velocity": 0.0, "effort": 0.0}
    assert 0 < rows[1].largest["velocity"] < 1e-15 and rows[1].largest["position"] == 0.0
    assert rows[2].largest["position"] == 0.25 and rows[2].where == (25, 2, "j0")
    assert c.largest()["effort"] == 0.25
    assert "11-12" in format_table(rows)


def test_within_tolerance_accepts_small_deviations_and_names_the_first_larger_one():
    tol = Tolerance(position=1e-3, velocity=1e-2, effort=1.0)
    c = Comparison(NAMES, tol, span=60)
    small = state(0.5)
    small[0][:] += 5e-4
    small[2][:] -= 0.9
    check(c, 3, 1, state(0.5), small)
    assert c.divergence is None
    assert c.rows()[0].largest["position"] == pytest.approx(5e-4)
    big = state(0.5)
    big[0][6] += 2e-3
    check(c, 70, 4, state(0.5), big)
    assert (c.divergence.tick, c.divergence.world, c.divergence.joint) == (70, 4, "j6")
    many = Comparison(NAMES, tol, span=60)  # several worlds at once: the first in world order
    a, b = state(0.5), state(0.5)
    a[2][5] += 2.0  # world 1: effort
    b[0][0] += 0.5  # world 3: position (larger, but a later world)
    many.check(5, np.array([1, 3]), np.stack([state(0.5)] * 2), np.stack([a, b]))
    d = many.divergence
    assert (d.world, d.quantity, d.joint) == (1, "effort", "j5"), d
    assert many.rows()[0].where == (5, 3, "j0") and many.rows()[0].states == 2
    nan = state(0.5)
    nan[1][0] = np.nan  # NaN is never within any tolerance
    c2 = Comparison(NAMES, Tolerance(1.0, 1.0, 1.0), span=60)
    check(c2, 1, 0, state(0.5), nan)
    assert c2.divergence is not None and c2.divergence.quantity == "velocity"


def test_tolerance_parsing_names_the_problem():
    assert Tolerance.parse("1e-3") == Tolerance(1e-3, 1e-3, 1e-3)
    assert Tolerance.parse("1e-3, 0.05,5") == Tolerance(1e-3, 0.05, 5.0)
    for bad, why in (("1,2", "one number or three"), ("x", "not a number"), ("-1", ">= 0")):
        with pytest.raises(ValueError, match=why):
            Tolerance.parse(bad)
    assert "|Δposition| ≤ 0.001 rad" in str(Tolerance(1e-3, 1.0, 1.0))


def test_table_rows_are_whole_seconds_of_ticks():
    assert table_span(0, 600) == 60
    assert table_span(0, 660) == 120
    assert table_span(100, 36100) == 3600


def test_only_the_cpu_is_bit_exact():
    assert bit_exact("cpu")
    assert not bit_exact("cuda:0") and not bit_exact("ray: 2 × cpu")


def test_a_module_warp_cannot_make_deterministic_falls_back_and_still_runs(tmp_path):
    """The bench's Warp-wide deterministic switch (bench/warp_modes.py) switches a whole process,
    so this runs in one of its own (a tiny CPU module)."""
    code = textwrap.dedent(
        """
        import warp as wp
        from bench import warp_modes
        warp_modes.enable()

        @wp.kernel
        def both(out: wp.array(dtype=float), x: wp.array(dtype=float)):
            i = wp.tid()
            out[i] = 1.0
            out[i] += x[i]  # written and accumulated: Warp refuses RUN_TO_RUN for this module

        x = wp.array([1.0, 2.0, 3.0], dtype=float, device="cpu")
        out = wp.zeros(3, dtype=float, device="cpu")
        wp.launch(both, dim=3, inputs=[out, x], device="cpu")
        print(out.numpy().tolist(), warp_modes.fallbacks, wp.config.deterministic.name)
        """
    )
    script = tmp_path / "fallback.py"  # Warp reads kernel source from files
    script.write_text(code)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run(
        [sys.executable, str(script)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    last = r.stdout.strip().splitlines()[-1]
    assert last == "[2.0, 3.0, 4.0] ['__main__'] RUN_TO_RUN", last


def test_the_prebuild_walk_notes_the_tick_modules_without_running_a_kernel():
    import warp as wp

    from bench.warp_modes import _noted_launches
    from service.engines.warp import WorldBatch

    seen: dict = {}
    with _noted_launches(seen):
        walked = WorldBatch(2, capture=False)
    assert wp.launch.__name__ == "launch"  # restored
    assert any(name.startswith("mujoco_warp._src.smooth") for name in seen)
    assert any("solver" in name or "_linesearch" in name for name in seen), sorted(seen)
    assert not walked.snapshot().position.any()  # nothing ran: not even the gather kernel
