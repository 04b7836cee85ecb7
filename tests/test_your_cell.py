"""Your own cell: `armfleet serve --scene my_cell.xml`, checked before anything is served.

Each bad scene stops `armfleet serve` with one message naming what is wrong (a real process,
nothing started); the example bin-picking cell is served and its parts are entities with
parameters of their own; the page's scene, the URDF and /tf see the cell.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from clients.testing import serve
from mjcf import MJCF_DIR
from service.core.sim.scene_check import MAX_CONTACTS, SceneError, check_scene
from service.engines.warp import NCONMAX
from service.surfaces.ros.tf_frames import FrameTree
from service.surfaces.ros.urdf import generate

EXAMPLE = MJCF_DIR / "examples" / "bin_picking.xml"
HOME = '<keyframe><key name="home" qpos="0 -1.57 1.57 -1.57 -1.57 0  0  0 0 0 0 0"/></keyframe>'
ARM = '<include file="ur10e_2f140.xml"/>'


def _cell(tmp_path: Path, body: str, arm: str = ARM, home: str = HOME) -> Path:
    path = tmp_path / "my_cell.xml"
    path.write_text(f'<mujoco model="mine">{arm}<worldbody>{body}</worldbody>{home}</mujoco>')
    return path


PART = (
    '<body name="part" pos="0.7 0.2 0.8"><freejoint/><geom type="box" size=".02 .02 .02"/></body>'
)
PILE = "".join(
    f'<body name="p{i}" pos="0.7 0.2 {0.1 + 0.01 * i}"><freejoint/>'
    f'<geom type="box" size=".1 .1 .1"/></body>'
    for i in range(12)
)


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (lambda t: _cell(t, "<body"), "does not parse"),
        (lambda t: _cell(t, PART, arm="", home=""), "has no arm"),
        (
            lambda t: _cell(t, PART, arm=ARM.replace('"/>', '"/><compiler/>')).with_name("x.xml"),
            "no such file",
        ),
        (lambda t: _cell(t, PART, home=""), "has no keyframe 'home'"),
        (
            lambda t: _cell(t, '<body pos="0.7 0.2 0.8"><freejoint/><geom size=".02"/></body>'),
            "has no name",
        ),
        (lambda t: _cell(t, PILE), f"more than the {MAX_CONTACTS} a world holds"),
    ],
)
def test_a_bad_scene_gets_one_clear_error(tmp_path, make, words):
    with pytest.raises(SceneError, match=words):
        check_scene(make(tmp_path))


def test_a_renamed_joint_is_named(tmp_path):
    arm = (MJCF_DIR / "ur10e_2f140.xml").read_text().replace('"elbow_joint"', '"elbow"')
    (tmp_path / "my_arm.xml").write_text(arm)
    with pytest.raises(SceneError, match="joint 'elbow_joint' is missing"):
        check_scene(_cell(tmp_path, PART, arm='<include file="my_arm.xml"/>'))


def test_the_contact_limit_is_the_warp_engines_capacity():
    assert MAX_CONTACTS == NCONMAX


def test_serve_refuses_a_bad_scene_before_serving_anything(tmp_path):
    bad = _cell(tmp_path, PART, home="")
    cmd = [sys.executable, "-m", "service.cli", "serve", "--scene", str(bad), "--port", "0"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0, out
    assert "has no keyframe 'home'" in out and "Uvicorn running" not in out


def test_the_example_cell_is_in_the_urdf_and_tf():
    robot = check_scene(EXAMPLE)
    assert robot.spec.names == check_scene(MJCF_DIR / "scene.xml").spec.names
    urdf = generate(robot.mjm, robot.spec)
    assert 'link name="bin"' in urdf  # the cell's fixed bodies are links; parts float free
    assert "part_box" not in urdf
    frames = FrameTree(robot.mjm).frames  # the cell's fixed bodies; parts are entities
    assert "bin" in frames and "wrist_3_link" in frames and "part_box" not in frames


@pytest.fixture(scope="module")
def cell_dir(tmp_path_factory):
    """The cell server's log and data (recordings) directory."""
    return tmp_path_factory.mktemp("cell")


@pytest.fixture(scope="module")
def cell(cell_dir):
    """The example cell, paused, on native MuJoCo (replay steps it on MuJoCo Warp)."""
    extra = ("--engine", "mujoco", "--scene", str(EXAMPLE), "--data-dir", str(cell_dir / "data"))
    with serve(worlds=4, mode="paused", extra_args=extra, log_dir=cell_dir) as srv:
        yield srv


def test_the_example_cell_is_served_with_its_parts_as_entities(cell):
    with httpx.Client(base_url=cell.url, timeout=10) as http:
        scene = http.get("/v1/scene").json()
        names = {b["name"] for b in scene["bodies"]}
        assert {"bin", "part_box", "part_cylinder", "part_ball", "wrist_3_link"} <= names
        parts = http.get("/v1/worlds/2/entities").json()["entities"]
        assert [p["name"] for p in parts] == ["part_box", "part_cylinder", "part_ball"]
        table = {p["name"] for p in http.get("/v1/params").json()["params"]}
        assert {"part_ball.mass", "part_cylinder.friction", "payload"} <= table
        ack = http.put("/v1/worlds/2/entities/part_ball", json={"position": [0.7, 0.17, 1.0]})
        assert ack.status_code == 200, ack.text
        far = http.put("/v1/worlds/2/entities/part_ball", json={"position": [0.7, 0.17, 1.7]})
        assert far.status_code == 422 and "z 0..1.6 m" in far.text  # the cell's own bounds
        http.post("/v1/sim/step", json={"ticks": 1})
        ball = http.get("/v1/worlds/2/entities/part_ball").json()
        assert ball["position"][2] == pytest.approx(1.0, abs=3e-3)


def test_a_recording_of_the_cell_replays_with_its_scene(cell, cell_dir):
    # The module's cell server (a server of its own cost ~2 CPU-s): the recording holds the
    # state it starts from, whatever the tests before this one did to the worlds.
    with httpx.Client(base_url=cell.url, timeout=60) as http:
        assert http.post("/v1/recordings", json={"name": "cell", "rate": 60}).status_code == 201
        put = {"position": [0.7, 0.17, 1.0], "angular": [0, 0, 3]}
        http.put("/v1/worlds/1/entities/part_box", json=put).raise_for_status()
        http.put("/v1/worlds/0/params", json={"params": {"part_ball.mass": 0.2}})
        http.post("/v1/sim/step", json={"ticks": 60}).raise_for_status()
        assert http.delete("/v1/recordings/current").status_code == 200
    path = str(cell_dir / "data" / "recordings" / "cell.mcap")
    cmd = [sys.executable, "-m", "service.cli", "replay", path]
    r = subprocess.run([*cmd, "--scene", str(EXAMPLE)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "identical" in r.stdout, r.stdout + r.stderr
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "another model" in r.stderr, r.stdout + r.stderr
