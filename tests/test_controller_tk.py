"""The Tk controller on a virtual X display, clicked with a real pointer (xdotool).

The window runs as `armfleet controller --url ... --world 1` in a subprocess. It is started
*before* the server, on a port where nothing listens yet, so its status line must first say
the server is gone and then recover when the server comes up on that port. With
ARMFLEET_TK_GEOMETRY_FILE set the window exports where its buttons are and what its labels
show; the tests click at those places and check the result through the server's REST API.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import (
    ELBOW,
    FINGER,
    HOME,
    JOINTS,
    ROOT,
    Server,
    free_port,
    serve,
    target_after,
    wait_for,
)
from jog_checks import assert_tcp_went, jogged_tcp, rotvec_matrix, settled_tcp

from clients import ArmfleetClient

pytest.importorskip("tkinter", reason="tkinter (python3-tk) is not installed")
for _tool in ("Xvfb", "xdotool"):
    if shutil.which(_tool) is None:
        pytest.skip(
            f"{_tool} is not installed (apt-get install xvfb xdotool)", allow_module_level=True
        )

TITLE = "Robot Joint Controller"
WORLD = 1


@pytest.fixture(scope="module")
def display() -> Iterator[str]:
    """A private Xvfb; it picks a free display number and tells it through -displayfd."""
    read_fd, write_fd = os.pipe()
    xvfb = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    try:
        with os.fdopen(read_fd) as pipe:
            number = pipe.readline().strip()
        assert number, "Xvfb did not report a display number"
        yield f":{number}"
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)


@dataclass
class TkApp:
    url: str
    process: subprocess.Popen[bytes]
    probe_path: Path
    display: str
    window: str = ""
    statuses: list[str] = field(default_factory=list)

    def probe(self) -> dict[str, Any]:
        with contextlib.suppress(FileNotFoundError, json.JSONDecodeError):
            return json.loads(self.probe_path.read_text())
        return {}

    def text(self, key: str) -> str | None:
        return self.probe().get("widgets", {}).get(key, {}).get("text")

    def xdotool(self, *args: str) -> str:
        env = {**os.environ, "DISPLAY": self.display}
        out = subprocess.run(
            ["xdotool", *args], env=env, capture_output=True, text=True, timeout=10
        )
        return out.stdout.strip()

    def click(self, key: str, fx: float = 0.5, fy: float = 0.5) -> None:
        """A real pointer click at a fraction (fx, fy) of the widget's box."""
        box = self.probe()["widgets"][key]
        x = int(box["x"] + box["width"] * fx)
        y = int(box["y"] + box["height"] * fy)
        self.xdotool("mousemove", "--window", self.window, str(x), str(y), "click", "1")


def _window_log(app: TkApp, log: Path) -> str:
    return f"probe: {app.probe()}\nlog:\n{log.read_text(errors='replace')}"


@pytest.fixture(scope="module")
def tk_app(
    display: str, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[tuple[TkApp, Server]]:
    tmp = tmp_path_factory.mktemp("tk")
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    probe = tmp / "geometry.json"
    log = tmp / "controller.log"
    env = {**os.environ, "DISPLAY": display, "ARMFLEET_TK_GEOMETRY_FILE": str(probe)}
    cmd = [sys.executable, "-m", "service.cli", "controller", "--url", url, "--world", str(WORLD)]
    with open(log, "wb") as out:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT)
    app = TkApp(url=url, process=proc, probe_path=probe, display=display)
    with contextlib.ExitStack() as stack:
        stack.callback(_stop, proc)
        # No server yet: the status line has to say so.
        gone = wait_for(
            lambda: "server gone" in app.probe().get("status", "") and app.probe()["status"],
            "the status line to report the server gone",
        )
        app.statuses.append(gone)
        server = stack.enter_context(serve(worlds=4, port=port, log_dir=tmp))
        connected = wait_for(
            lambda: app.probe().get("connected") and app.probe()["status"],
            "the window to connect",
            timeout=20,
        )
        app.statuses.append(connected)
        # the joint values of world 1 are on show once info and a state frame arrived
        wait_for(lambda: app.probe().get("nworld") == 4, "/v1/info in the window")
        app.window = wait_for(
            lambda: app.xdotool("search", "--name", f"^{TITLE}$").splitlines()[:1],
            "the window on the X display",
        )[0]
        yield app, server
        assert proc.poll() is None, _window_log(app, log)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@pytest.fixture
def app(tk_app: tuple[TkApp, Server]) -> TkApp:
    app, _ = tk_app
    assert app.probe()["world"] == WORLD
    return app


@pytest.fixture
def client(tk_app: tuple[TkApp, Server]) -> Iterator[ArmfleetClient]:
    with ArmfleetClient(tk_app[1].url) as c:
        yield c


def label_shows(app: TkApp, key: str, text: str) -> None:
    wait_for(lambda: app.text(key) == text, f"{key} to show {text!r} (shows {app.text(key)!r})")


# -- tests ----------------------------------------------------------------------------------


def test_status_line_says_server_gone_until_it_starts_then_connected(app: TkApp) -> None:
    gone, connected = app.statuses
    assert "server gone (connection refused)" in gone
    assert connected.startswith(f"Connected to {app.url}: world 1")
    wait_for(lambda: "world 1 (0..3)" in app.probe()["status"], "the world count from /v1/info")


def test_window_has_the_seed_layout_one_row_per_joint(app: TkApp) -> None:
    assert app.xdotool("getwindowname", app.window) == TITLE
    probe = app.probe()
    assert probe["title"] == TITLE
    for i, name in enumerate(JOINTS):
        assert app.text(f"label:{name}") == f"[{i}] {name}"
        assert app.text(f"up:{name}") == "Up (+0.1)"
        assert app.text(f"down:{name}") == "Down (-0.1)"
        # one row: label, target, measured and buttons share a line, rows go down the window
        row = [probe["widgets"][f"{k}:{name}"] for k in ("label", "target", "up", "down")]
        assert [w["x"] for w in row] == sorted(w["x"] for w in row)
        assert max(w["y"] for w in row) - min(w["y"] for w in row) < 10
    ys = [probe["widgets"][f"up:{name}"]["y"] for name in JOINTS]
    assert ys == sorted(ys)
    assert {app.text("open"), app.text("close"), app.text("reset")} == {"Open", "Close", "Reset"}


def test_up_button_click_raises_the_world_target(app: TkApp, client: ArmfleetClient) -> None:
    before = client.state(WORLD).target
    app.click("up:elbow_joint")
    after = target_after(client, WORLD, lambda s: s.target[ELBOW] != before[ELBOW])
    assert after[ELBOW] == pytest.approx(before[ELBOW] + 0.1)
    assert list(after[:ELBOW]) == list(before[:ELBOW])
    label_shows(app, "target:elbow_joint", f"{after[ELBOW]:.2f}")


def test_down_button_click_lowers_the_world_target(app: TkApp, client: ArmfleetClient) -> None:
    before = client.state(WORLD).target
    app.click("down:shoulder_pan_joint")
    after = target_after(client, WORLD, lambda s: s.target[0] != before[0])
    assert after[0] == pytest.approx(before[0] - 0.1)
    label_shows(app, "target:shoulder_pan_joint", f"{after[0]:.2f}")


def test_close_and_open_buttons_set_the_gripper_target(app: TkApp, client: ArmfleetClient) -> None:
    client.set_targets(WORLD, {"finger_joint": 0.3})
    label_shows(app, "target:finger_joint", "0.30")
    app.click("close")
    assert target_after(client, WORLD, lambda s: s.target[FINGER] > 0.5)[FINGER] == (
        pytest.approx(0.7)
    )
    label_shows(app, "target:finger_joint", "0.70")
    # Up at the limit: the server clamps, and the label shows what the server replied
    app.click("up:finger_joint")
    wait_for(lambda: "clamped" in app.probe()["status"], "the clamp notice")
    assert client.state(WORLD).target[FINGER] == pytest.approx(0.7)
    assert app.text("target:finger_joint") == "0.70"
    app.click("open")
    assert target_after(client, WORLD, lambda s: s.target[FINGER] < 0.5)[FINGER] == 0.0
    label_shows(app, "target:finger_joint", "0.00")


def test_reset_button_click_returns_targets_home(app: TkApp, client: ArmfleetClient) -> None:
    client.set_targets(WORLD, {"wrist_3_joint": 0.8})
    label_shows(app, "target:wrist_3_joint", "0.80")
    app.click("reset")
    assert target_after(client, WORLD, lambda s: s.target[5] == 0.0) == pytest.approx(HOME)
    label_shows(app, "target:wrist_3_joint", "0.00")
    label_shows(app, "target:elbow_joint", "1.57")


def test_measured_position_follows_the_arm_live(app: TkApp, client: ArmfleetClient) -> None:
    client.set_targets(WORLD, {"wrist_2_joint": -1.0})
    wait_for(
        lambda: abs(float(app.text("measured:wrist_2_joint") or "nan") + 1.0) <= 0.02,
        "the measured wrist_2 position to reach -1.00",
    )
    client.reset(WORLD)


def test_world_selector_switches_the_controlled_world(app: TkApp, client: ArmfleetClient) -> None:
    client.reset([1, 2])
    app.click("world", fx=0.93, fy=0.25)  # the spinbox's up arrow
    try:
        wait_for(lambda: app.probe()["world"] == 2, "world 2 to be selected")
        wait_for(lambda: "world 2" in app.probe()["status"], "the status line to say world 2")
        app.click("up:elbow_joint")
        after = target_after(client, 2, lambda s: s.target[ELBOW] != HOME[ELBOW])
        assert after[ELBOW] == pytest.approx(HOME[ELBOW] + 0.1)
        assert client.state(WORLD).target[ELBOW] == pytest.approx(HOME[ELBOW])
    finally:
        app.click("world", fx=0.93, fy=0.75)  # the down arrow: back to world 1
        wait_for(lambda: app.probe()["world"] == WORLD, "world 1 to be selected again")
        client.reset([1, 2])


def test_window_has_the_jog_block_under_the_joint_rows(app: TkApp) -> None:
    probe = app.probe()
    assert probe["jog"] == {"frame": "base", "step": "10 mm / 0.05 rad"}
    names = ("X", "Y", "Z", "Rx", "Ry", "Rz")
    for axis, name in zip(("x", "y", "z", "rx", "ry", "rz"), names, strict=True):
        assert app.text(f"jog:-{axis}") == f"-{name}" and app.text(f"jog:+{axis}") == f"+{name}"
    assert {app.text("frame:base"), app.text("frame:tool")} == {"base", "tool"}
    lowest_row = probe["widgets"]["up:finger_joint"]["y"]
    assert min(probe["widgets"][f"jog:{s}{a}"]["y"] for s in "+-" for a in "xyz") > lowest_row


def test_plus_z_click_raises_the_tcp_by_the_step(app: TkApp, client: ArmfleetClient) -> None:
    client.reset(WORLD)
    before = settled_tcp(client, WORLD)
    app.click("jog:+z")
    after = jogged_tcp(client, WORLD, before)
    assert_tcp_went(before, after, [0, 0, 0.01])
    turned = rotvec_matrix(after["tcp"][3:]).T @ rotvec_matrix(before["tcp"][3:])
    assert turned == pytest.approx(np.eye(3), abs=1e-3)  # a translation: the tool kept its turn
    label_shows(app, "target:elbow_joint", f"{client.state(WORLD).target[ELBOW]:.2f}")
    client.reset(WORLD)


def test_tool_frame_and_a_finer_step_move_along_the_tools_z(
    app: TkApp, client: ArmfleetClient
) -> None:
    client.reset(WORLD)
    before = settled_tcp(client, WORLD)
    app.click("frame:tool")
    app.click("step", fx=0.95, fy=0.75)  # the spinbox's down arrow: the finer preset
    try:
        wait_for(
            lambda: app.probe()["jog"] == {"frame": "tool", "step": "1 mm / 0.01 rad"},
            "the tool frame and the 1 mm step in the window",
        )
        app.click("jog:+z")
        after = jogged_tcp(client, WORLD, before)
        # along the tool's z axis (the third column of its rotation), which at home points
        # down: the same button in the base frame went up
        tool_z = rotvec_matrix(before["target_tcp"][3:])[:, 2]
        assert tool_z[2] < -0.9
        assert_tcp_went(before, after, 0.001 * tool_z)
    finally:
        app.click("frame:base")
        app.click("step", fx=0.95, fy=0.25)  # the up arrow: back to 10 mm / 0.05 rad
        wait_for(
            lambda: app.probe()["jog"] == {"frame": "base", "step": "10 mm / 0.05 rad"},
            "the window back on base frame and 10 mm",
        )
        client.reset(WORLD)


def test_a_jog_out_of_reach_shows_the_servers_reason(app: TkApp, client: ArmfleetClient) -> None:
    # The arm stretched out flat away from the table (shoulder lift -pi, elbow 0; towards the
    # table it would go through it, a protective stop): one more step outwards is beyond its
    # reach. Jogs start from the targets, so the arm need not get there first.
    client.set_targets(WORLD, {"shoulder_lift_joint": -3.1416, "elbow_joint": 0.0})
    try:
        stretched = client.state(WORLD).target
        outward = "-x" if client.tcp(WORLD)["target_tcp"][0] < 0 else "+x"
        app.click(f"jog:{outward}")
        wait_for(lambda: "leaves the arm's reach" in app.probe()["status"], "the refusal")
        status = app.probe()["status"]
        assert f"Jog {outward.upper()} (base) failed: HTTP 422: body.step:" in status
        assert list(client.state(WORLD).target) == list(stretched)  # nothing moved
        assert app.process.poll() is None
    finally:
        client.reset(WORLD)


def test_screenshot_of_the_window(app: TkApp, tmp_path: Path) -> None:
    """Saved under the test's tmp dir; ARMFLEET_UPDATE_DOCS=1 writes docs/controller_tk.png."""
    image_grab = pytest.importorskip("PIL.ImageGrab", reason="Pillow takes the screenshot")
    size = app.probe()["window"]
    where = dict(
        line.split("=", 1)
        for line in app.xdotool("getwindowgeometry", "--shell", app.window).split()
    )
    x, y = int(where["X"]), int(where["Y"])
    bbox = (x, y, x + size["width"], y + size["height"])
    shot = image_grab.grab(bbox=bbox, xdisplay=app.display)
    assert shot.size == (size["width"], size["height"])
    assert len(shot.convert("L").getcolors(256) or []) > 8  # drawn, not a blank frame
    out = tmp_path / "controller_tk.png"
    shot.save(out)
    if os.environ.get("ARMFLEET_UPDATE_DOCS") == "1":
        (ROOT / "docs").mkdir(exist_ok=True)
        shutil.copy(out, ROOT / "docs" / "controller_tk.png")
