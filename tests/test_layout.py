"""The code's shape: layers without cycles, small modules, surfaces as plug-ins (issue 16).

The import graph is drawn from the source text (scripts/import_graph.py), TYPE_CHECKING and
function-level imports included, so an import that runs only on some path still counts.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from service.core.sim.batch import Batch, Renderable, Restorable, Supervised
from service.core.sim.settings import SimSettings
from service.core.surface import Routed, Surface
from service.settings import Settings
from service.surfaces.registry import REGISTRY, build_surfaces
from service.surfaces.ros.settings import Ros2Settings
from tests import ros2_judge

pytestmark = pytest.mark.usefixtures("hermetic_settings")  # Settings built here read no env

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 400


def _import_graph():
    spec = importlib.util.spec_from_file_location("import_graph", ROOT / "scripts/import_graph.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_import_graph_has_no_cycles_and_no_upward_imports() -> None:
    ig = _import_graph()
    graph = ig.graph()
    assert "service.core.sim.loop" in graph and "service.surfaces.registry" in graph
    # the bench and the ROS node (packaging/armfleet-ros) are drawn too
    assert "bench.figures" in graph and "armfleet_ros.node" in graph
    assert ig.cycles(graph) == []
    assert ig.upward(graph) == []


def test_nothing_outside_the_client_imports_its_private_modules() -> None:
    """The client's face is its public modules (`clients.calls`, `clients.stream`, ...): the
    service, the ROS node, the bench and the tests use those, never `clients._*` (issue 37)."""
    ig = _import_graph()
    assert ig.private(ig.graph()) == []
    # the graph holds no test module: read the tests' imports too
    tests = {
        m: ig.imports_of(m, p, {**ig.discover(), m: p})
        for p in (ROOT / "tests").rglob("*.py")
        for m in [f"tests.{p.stem}"]
    }
    assert ig.private(tests) == []
    bad = {"armfleet_ros.x": {"clients._http"}, "clients.client": {"clients._http"}}
    assert ig.private(bad) == [("armfleet_ros.x", "clients._http")]  # the check can fail


def test_the_checker_sees_a_cycle_and_an_upward_import() -> None:
    """The check above could fail: a made-up graph with both faults is caught."""
    ig = _import_graph()
    bad = {
        "service.core.a": {"service.core.b"},
        "service.core.b": {"service.core.a", "service.surfaces.x"},
        "service.surfaces.x": set(),
    }
    assert ig.cycles(bad) == [["service.core.a", "service.core.b"]]
    assert ig.upward(bad) == [("service.core.b", "service.surfaces.x")]


def test_no_module_over_the_line_limit() -> None:
    long = {
        str(p.relative_to(ROOT)): n
        for folder in ("service", "clients", "packaging")
        for p in (ROOT / folder).rglob("*.py")
        if (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert long == {}


def test_importing_the_contract_and_building_the_app_compile_no_model() -> None:
    code = (
        "import service.core.contract.replies, service.app, service.core.sim.robot as r;"
        "service.app.create_app();"
        "print(r.default_spec.cache_info().currsize)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "0"


def test_the_registry_builds_what_the_settings_ask_for(monkeypatch: pytest.MonkeyPatch) -> None:
    plain = build_surfaces(Settings(worlds=4))
    assert [s.name for s in plain] == ["rosbridge"]  # always there
    # --ros2 needs a ROS 2 to run its node on: the judge's, when it is built
    judge = ros2_judge.root()
    ros = {"ros2": True, "ros2_python": ros2_judge.python()} if judge else {}
    if judge:  # as in a shell that sourced it
        for key, value in ros2_judge.env().items():
            monkeypatch.setenv(key, value)
    full = build_surfaces(
        Settings(
            worlds=4,
            foxglove=True,
            ros2_worlds="0-1",
            camera_record=Path("c.mcap"),
            ur=True,  # built, not bound: its ports open when the surface starts
            **ros,
        )
    )
    wanted = [e.name for e in REGISTRY if judge or e.name != "ros2"]
    assert [s.name for s in full] == wanted
    for surface in full:
        assert isinstance(surface, Surface)
    # Routes come from the surfaces that have them: rosbridge's socket and GET /v1/ros, and
    # the UR surface's GET /v1/ur.
    assert [s.name for s in full if isinstance(s, Routed)] == ["rosbridge", "ur"]
    assert len(full.routers()) == 2


def test_a_bad_world_list_is_refused_before_anything_is_built() -> None:
    with pytest.raises(ValueError, match="ros2_worlds"):
        unchecked = Settings.model_construct(
            sim=SimSettings(worlds=4), ros2=Ros2Settings(worlds="9")
        )
        build_surfaces(unchecked)


def test_engines_declare_their_capabilities() -> None:
    """Optional capabilities are protocols the engine classes take on, checked by isinstance."""
    from service.engines.native import NativeBatch
    from service.engines.ray_shards import RayBatch
    from service.engines.shards import ShardedBatch
    from service.engines.warp import WorldBatch

    for engine in (WorldBatch, NativeBatch, ShardedBatch, RayBatch):
        assert Batch in engine.__mro__ and Restorable in engine.__mro__
    assert Supervised in ShardedBatch.__mro__
    for engine in (WorldBatch, NativeBatch, ShardedBatch):  # cameras see their worlds
        assert Renderable in engine.__mro__
    assert Supervised not in WorldBatch.__mro__
