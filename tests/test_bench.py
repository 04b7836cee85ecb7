"""Smoke test of the benchmark's throughput section: every engine runs and reports a rate.

Tiny sizes and durations; no assertion on how fast anything is (the CI box is shared).
"""

from __future__ import annotations

import json
import math

from bench import common, throughput
from service.physics import tick_timing


def test_throughput_section_reports_every_engine(tmp_path):
    payload = throughput.run(
        [1, 4], "cpu", min_time=0.01, warmup_time=0.0, rollout_threads=2, progress=None
    )
    path = common.write_json("throughput.json", payload, tmp_path)
    data = json.loads(path.read_text())

    assert data["errors"] == {}
    assert set(data["engines"]) == set(throughput.ENGINES)
    substeps, dt = tick_timing(common.CONTROL_HZ, common.PHYSICS_DT)
    assert data["substeps"] == substeps and math.isclose(data["physics_dt"], dt)
    assert math.isclose(data["model"]["timestep"], data["physics_dt"])
    assert data["machine"]["mujoco"] and data["machine"]["warp"]
    for n in ("1", "4"):
        engines = data["results"][n]["engines"]
        assert set(engines) == set(throughput.ENGINES)
        for name, res in engines.items():
            assert res["world_steps_per_s"] > 0, (n, name)
            assert res["calls"] >= 1 and res["elapsed_s"] > 0, (n, name)
            assert res.get("finite", True), (n, name)
        assert engines[throughput.ENGINE]["captured"]
        assert engines[throughput.ENGINE]["faults"] == 0
        assert all(r > 0 for r in data["results"][n]["ratios"].values())
