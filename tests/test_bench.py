"""The bench end to end: the runner runs section 1 (throughput) quick at two tiny sizes.

Real engines, real result files; no assertion on how fast anything is (the CI box is shared).
"""

from __future__ import annotations

import importlib.util
import json
import math

import pytest

from bench import common, cpu_meter, registry, runner, throughput
from service.core.sim.physics import tick_timing


def test_every_section_is_registered_once_with_a_stable_file_name():
    sections = registry.discover()
    names = {s.number: s.name for s in sections.values()}
    assert names == {
        1: "throughput",
        2: "service_fast",
        3: "realtime_capacity",
        4: "latency",
        5: "http",
        6: "startup",
        7: "service_fast_binary",
    } | {k: v for k, v in names.items() if k > 7}  # sections added later keep these
    with pytest.raises(ValueError, match="section 1 is taken"):
        registry.section(1, "another")(lambda ctx: registry.Result([]))
    with pytest.raises(SystemExit, match="no section"):
        runner.choose(sections, [999], "cpu")


def test_the_cpu_meter_says_who_used_the_cores_and_what_a_tick_and_a_command_cost():
    """Section 31's arithmetic: a worker that exited or started within the window counts for
    nothing (its CPU is not known on both sides), the rest of the box is what the three
    parties did not use, and a command's cost is what the server spent beyond its ticks."""
    a = cpu_meter.Reading(0.0, server=1.0, workers={7: 2.0, 9: 5.0}, clients=0.5, box=10.0)
    b = cpu_meter.Reading(2.0, server=2.0, workers={7: 3.6, 8: 9.9}, clients=0.9, box=14.0)
    used = cpu_meter.between(a, b, ticks=100)
    assert used["cores_server"] == 0.5 and used["cores_workers"] == pytest.approx(0.8)
    assert used["cores_clients"] == 0.2 and used["cores_others"] == pytest.approx(0.5)
    assert used["server_ms_per_tick"] == 10.0 and used["workers_ms_per_tick"] == 16.0
    idle = {"server_ms_per_tick": 5.0, "workers_ms_per_tick": 5.0}
    costs = cpu_meter.per_command(idle, used, handled=100, sent=200)
    assert costs == {"server_ms_per_command": 16.0, "clients_ms_per_command": 2.0}


def test_throughput_section_through_the_runner(tmp_path):
    report = runner.run([1], quick=True, worlds=[1, 4], out_dir=tmp_path, say=lambda _m: None)
    assert report["errors"] == {} and report["sections_run"] == [1]
    data = json.loads((tmp_path / "throughput.json").read_text())
    assert json.loads((tmp_path / "results.json").read_text())["sections"]["throughput"] == data

    assert data["errors"] == {}
    assert data["section"] == "throughput" and data["number"] == 1 and data["quick"]
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
    # The table's rows: one per size, a rate for every engine and the engine's ratios.
    assert [row["worlds"] for row in data["rows"]] == [1, 4]
    assert all(v > 0 for row in data["rows"] for v in row.values())
    assert len(data["rows"][0]) == 1 + len(throughput.ENGINES) + len(throughput.ENGINES) - 1
    if importlib.util.find_spec("matplotlib"):
        assert report["plot"] == str(tmp_path / "throughput.png")
        assert (tmp_path / "throughput.png").stat().st_size > 0


def test_physics_step_and_kernel_sections_through_the_runner(tmp_path):
    """Sections 12 and 13 (issue 13) at two worlds: both engines at both steps, warp's kernels."""
    report = runner.run([12, 13], quick=True, worlds=[2], out_dir=tmp_path, say=lambda _m: None)
    assert report["errors"] == {} and report["sections_run"] == [12, 13]
    step = json.loads((tmp_path / "physics_step.json").read_text())
    res = step["results"]["2"]
    for engine in ("mujoco", "warp"):
        assert res[f"{engine}_old"]["substeps"] == 8
        assert res[f"{engine}_new"]["substeps"] == tick_timing(60.0, common.PHYSICS_DT)[0]
        assert res[f"{engine}_gain"] > 0
    prof = json.loads((tmp_path / "kernels.json").read_text())["results"]["2"]
    assert prof["launches_per_tick"] > 50  # every substep's kernels were seen
    assert math.isclose(sum(k["share"] for k in prof["kernels"]), 1.0)


def test_the_capacity_ladder_stops_at_the_first_rung_that_fails_in_any_round():
    """Section 11's search (bench/capacity.py): a rung holds only when all its rounds pass."""
    from bench.capacity import ladder

    rtf = iter([1.0, 1.0, 0.995, 0.999, 1.0, 0.97, 1.0])  # rung 0.9 fails in its second round
    calls = []

    def measure(share: float) -> dict:
        calls.append(share)
        return {"nworld": int(share * 1000), "realtime_factor": next(rtf)}

    held, runs = ladder(measure, (0.8, 0.85, 0.9, 0.95), rounds=2)
    assert held == 0.85
    assert calls == [0.8, 0.8, 0.85, 0.85, 0.9, 0.9]  # 0.95 never tried
    assert [r["passed"] for r in runs] == [True, True, True, True, True, False]
    held, runs = ladder(lambda s: {"nworld": 8, "realtime_factor": 0.5}, (0.8, 0.9), rounds=2)
    assert held is None and len(runs) == 1


def test_a_capacity_run_on_an_unsteady_machine_is_measured_again():
    from bench.capacity import ladder

    results = iter(
        [
            {"nworld": 800, "realtime_factor": 0.9, "steady": False},  # not counted
            {"nworld": 800, "realtime_factor": 1.0, "steady": True},
            {"nworld": 800, "realtime_factor": 0.9, "steady": False},
            {"nworld": 800, "realtime_factor": 0.9, "steady": False},
            {"nworld": 800, "realtime_factor": 0.95, "steady": False},  # third try counts
        ]
    )
    held, runs = ladder(lambda _s: next(results), (0.8,), rounds=2)
    assert held is None
    assert [r["counted"] for r in runs] == [False, True, False, False, True]


def test_the_capacity_ladder_goes_down_when_its_first_rung_fails():
    from bench.capacity import ladder

    rtf = {0.85: 0.95, 0.8: 0.97, 0.75: 1.0}
    held, runs = ladder(
        lambda s: {"nworld": 1, "realtime_factor": rtf[s]}, (0.85, 0.9), rounds=2, below=(0.8, 0.75)
    )
    assert held == 0.75 and [r["rung"] for r in runs] == [0.85, 0.8, 0.75, 0.75]
