"""A cell's own step options are not replaced without a word (issue 38 item 5): `serve --scene`
says in one line at start what of the cell's <option> it replaced (timestep, solver) and how
to keep them; a cell with the custom numeric `armfleet_own_physics` = 1 is stepped at its own
timestep with its own solver, and a timestep that does not divide the control tick is said in
one line too. Real servers; their own log and GET /v1/info are the judges."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest
from conftest import running_server

from mjcf import MJCF_DIR

EXAMPLE = MJCF_DIR / "examples" / "bin_picking.xml"
KEEP = '<custom><numeric name="armfleet_own_physics" data="1"/></custom>'


def _cell(tmp: Path, keep: bool) -> Path:
    """The example cell (timestep 2 ms, MuJoCo's default Newton solver), kept or not."""
    text = EXAMPLE.read_text()
    if keep:
        text = text.replace("</mujoco>", f"  {KEEP}\n</mujoco>")
    path = tmp / ("kept.xml" if keep else "cell.xml")
    path.write_text(text)
    return path


def _physics_lines(log: str) -> list[str]:
    return [line for line in log.splitlines() if "physics: the cell's" in line]


def test_replaced_options_are_said_in_one_line(tmp_path: Path) -> None:
    extra = ("--engine", "mujoco", "--scene", str(_cell(tmp_path, keep=False)))
    with running_server(tmp_path, worlds=1, mode="paused", extra=extra) as srv:
        info = httpx.get(f"{srv.url}/v1/info", timeout=10).json()
        lines = _physics_lines(srv.log())
    assert info["physics_dt"] == pytest.approx(1 / 120)  # armfleet's own step
    assert len(lines) == 1, srv.log()
    line = lines[0]
    # native MuJoCo steps with Newton (physics.ENGINE_SOLVER), the cell's own: not replaced
    assert "timestep 2 ms replaced" in line and "solver replaced" not in line, line
    assert "Newton solver" in line and "implicitfast integrator kept" in line, line
    assert '<numeric name="armfleet_own_physics" data="1"/>' in line, line


@pytest.mark.parametrize(("hz", "divides"), [(50, True), (60, False)])
def test_a_cell_that_keeps_its_physics_is_stepped_at_its_timestep(
    tmp_path: Path, hz: int, divides: bool
) -> None:
    cell = _cell(tmp_path, keep=True)
    extra = ("--engine", "mujoco", "--scene", str(cell), "--control-hz", str(hz))
    with running_server(tmp_path, worlds=1, mode="paused", extra=extra) as srv:
        info = httpx.get(f"{srv.url}/v1/info", timeout=10).json()
        httpx.post(f"{srv.url}/v1/sim/step", json={"ticks": 5}, timeout=30).raise_for_status()
        lines = _physics_lines(srv.log())
    substeps = round(1 / hz / 0.002)
    assert info["physics_dt"] == pytest.approx(1 / hz / substeps)
    if divides:
        assert info["physics_dt"] == pytest.approx(0.002) and lines == [], lines
    else:  # 1/60 s is 8.33 steps of 2 ms: 8 of 2.083 ms, said once
        assert len(lines) == 1 and "does not divide the 1/60 s control tick" in lines[0], lines
        assert "8 substeps of 2.083 ms" in lines[0] and "newton solver" in lines[0], lines
