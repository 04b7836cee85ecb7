"""The terminal controller in a real terminal (tmux), driven by real keystrokes.

`armfleet controller --terminal --url ... --world 2` runs in a detached tmux session on a
private tmux socket; `tmux send-keys` types, `tmux capture-pane -p` reads the screen, and the
server's REST API says what the keys did.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from conftest import ELBOW, FINGER, HOME, JOINTS, ROOT, Server, target_after, wait_for
from jog_checks import assert_tcp_went, jogged_tcp, rotvec_matrix, settled_tcp, tcp_moved

from clients import ArmfleetClient

if shutil.which("tmux") is None:
    pytest.skip("tmux is not installed (apt-get install tmux)", allow_module_level=True)

WORLD = 2
ROW = re.compile(r"^\s*(>?)\s*\[(\d)\] (\w+)\s+(-?\d+\.\d\d|--)\s+(-?\d+\.\d\d|--)\s*$")
JOG_ROW = re.compile(r"^\s*(>?)\s*jog (\w+) \[(m|rad)\]\s+±(\S+)\s*$")
AXES = ["X", "Y", "Z", "Rx", "Ry", "Rz"]


@dataclass
class Terminal:
    socket: str
    session: str

    def tmux(self, *args: str) -> str:
        out = subprocess.run(
            ["tmux", "-L", self.socket, *args], capture_output=True, text=True, timeout=10
        )
        return out.stdout

    def screen(self) -> str:
        return self.tmux("capture-pane", "-p", "-t", self.session)

    def keys(self, *keys: str) -> None:
        for key in keys:  # one at a time, as a person types
            self.tmux("send-keys", "-t", self.session, key)
            time.sleep(0.05)

    def rows(self) -> dict[str, dict[str, Any]]:
        """The joint rows on screen: name → {index, selected, target, measured}."""
        out = {}
        for line in self.screen().splitlines():
            m = ROW.match(line)
            if m:
                out[m[3]] = {
                    "index": int(m[2]),
                    "selected": m[1] == ">",
                    "target": m[4],
                    "measured": m[5],
                }
        return out

    def jog_rows(self) -> dict[str, dict[str, Any]]:
        """The jog rows on screen: axis (X .. Rz) → {selected, unit, step}."""
        out = {}
        for line in self.screen().splitlines():
            m = JOG_ROW.match(line)
            if m:
                out[m[2]] = {"selected": m[1] == ">", "unit": m[3], "step": m[4]}
        return out

    def said(self, text: str) -> bool:
        """Whether the screen shows `text`, however the status line wrapped it."""
        return " ".join(text.split()) in " ".join(self.screen().split())

    def status(self) -> str:
        return next((ln for ln in self.screen().splitlines() if "http://" in ln), "")

    def selected(self) -> int:
        """The cursor's row: a joint's index, or 7 + the jog axis's for a jog row."""
        joints = [r["index"] for r in self.rows().values() if r["selected"]]
        jogs = [len(JOINTS) + AXES.index(a) for a, r in self.jog_rows().items() if r["selected"]]
        return (joints + jogs)[0]

    def select(self, row: int) -> None:
        """Move the row cursor to `row` (a joint, or 7 + a jog axis) with j/k, as a user would."""
        step = row - self.selected()
        self.keys(*(["j"] * step if step > 0 else ["k"] * -step))
        wait_for(lambda: self.selected() == row, f"row {row} to be selected")

    def shows(self, joint: str, target: str) -> None:
        wait_for(
            lambda: self.rows().get(joint, {}).get("target") == target,
            f"{joint} to show target {target} on screen:\n{self.screen()}",
        )


def start_terminal(server_url: str, name: str) -> Terminal:
    cmd = shlex.join(
        [sys.executable, "-m", "service.cli", "controller", "--terminal", "--url", server_url]
        + ["--world", str(WORLD)]
    )
    term = Terminal(socket=f"armfleet-test-{name}", session="ctl")
    term.tmux(
        "new-session", "-d", "-s", term.session, "-x", "120", "-y", "40", "-c", str(ROOT),
        f"{cmd}; echo EXITED $?; sleep 60",
    )  # fmt: skip
    return term


@pytest.fixture(scope="module")
def term(server: Server) -> Iterator[Terminal]:
    term = start_terminal(server.url, f"{id(server)}")
    try:
        wait_for(lambda: "Connected to" in term.status(), "the controller to connect", 30)
        wait_for(lambda: "(0..3)" in term.status(), "the world count from /v1/info")
        yield term
    finally:
        term.tmux("kill-server")


@pytest.fixture
def client(server: Server, term: Terminal) -> Iterator[ArmfleetClient]:
    with ArmfleetClient(server.url) as c:
        c.reset(WORLD)
        term.shows("elbow_joint", "1.57")
        yield c


def test_screen_shows_the_seven_joint_rows_with_live_values(
    term: Terminal, client: ArmfleetClient
) -> None:
    screen = term.screen()
    assert "Robot Joint Controller: world 2 (0..3)" in screen
    rows = term.rows()
    assert list(rows) == JOINTS
    assert [r["index"] for r in rows.values()] == list(range(7))
    assert [float(r["target"]) for r in rows.values()] == pytest.approx(HOME)
    assert float(rows["elbow_joint"]["measured"]) == pytest.approx(1.57, abs=0.02)
    assert f"Connected to {client.url}: world 2 (0..3), tick" in term.status()


def test_plus_key_raises_the_selected_joint_target(term: Terminal, client: ArmfleetClient) -> None:
    term.select(ELBOW)
    term.keys("+")
    after = target_after(client, WORLD, lambda s: s.target[ELBOW] != HOME[ELBOW])
    assert after[ELBOW] == pytest.approx(1.67)
    term.shows("elbow_joint", "1.67")
    term.keys("Right")  # right arrow is +0.1 too
    term.shows("elbow_joint", "1.77")
    assert target_after(client, WORLD, lambda s: s.target[ELBOW] > 1.7)[ELBOW] == (
        pytest.approx(1.77)
    )


def test_minus_key_and_arrows_pick_and_lower_a_joint(
    term: Terminal, client: ArmfleetClient
) -> None:
    term.select(0)
    term.keys("Down")  # the arrow moves the cursor like j
    wait_for(lambda: term.selected() == 1, "the cursor on row 1")
    term.keys("-", "Left")
    term.shows("shoulder_lift_joint", "-1.77")
    after = target_after(client, WORLD, lambda s: s.target[1] < -1.7)
    assert after[1] == pytest.approx(-1.77)
    assert after[0] == pytest.approx(0.0)


def test_c_and_o_keys_close_and_open_the_gripper(term: Terminal, client: ArmfleetClient) -> None:
    term.keys("c")
    term.shows("finger_joint", "0.70")
    assert target_after(client, WORLD, lambda s: s.target[FINGER] > 0)[FINGER] == (
        pytest.approx(0.7)
    )
    term.keys("o")
    term.shows("finger_joint", "0.00")
    assert target_after(client, WORLD, lambda s: s.target[FINGER] == 0)[FINGER] == 0.0


def test_r_key_resets_the_world(term: Terminal, client: ArmfleetClient) -> None:
    client.set_targets(WORLD, {"wrist_3_joint": -0.5, "finger_joint": 0.4})
    term.shows("wrist_3_joint", "-0.50")
    term.keys("r")
    term.shows("wrist_3_joint", "0.00")
    term.shows("finger_joint", "0.00")
    assert target_after(client, WORLD, lambda s: s.target[5] == 0) == pytest.approx(HOME)
    assert "world 2 reset" in term.status()


def test_w_key_switches_world_and_keys_drive_the_new_one(
    term: Terminal, client: ArmfleetClient
) -> None:
    client.reset(3)
    term.keys("w")
    try:
        wait_for(lambda: "world 3 (0..3)" in term.screen(), "the title to say world 3")
        wait_for(lambda: "world 3 (0..3), tick" in term.status(), "frames of world 3")
        term.select(ELBOW)
        term.keys("+")
        after = target_after(client, 3, lambda s: s.target[ELBOW] != HOME[ELBOW])
        assert after[ELBOW] == pytest.approx(1.67)
        assert client.state(WORLD).target[ELBOW] == pytest.approx(1.57)
    finally:
        term.keys("W")
        wait_for(lambda: "world 2 (0..3), tick" in term.status(), "back on world 2")
        client.reset(3)


def test_screen_shows_the_jog_rows_and_s_changes_their_step(term: Terminal) -> None:
    rows = term.jog_rows()
    assert list(rows) == AXES, term.screen()
    assert [(r["unit"], r["step"]) for r in rows.values()] == [("m", "0.01")] * 3 + [
        ("rad", "0.05")
    ] * 3
    assert term.said("Jog: base frame, step 10 mm / 0.05 rad")
    term.keys("s")
    wait_for(lambda: term.said("step 50 mm / 0.1 rad"), "the coarser step on screen")
    assert term.jog_rows()["Z"]["step"] == "0.05" and term.jog_rows()["Rz"]["step"] == "0.1"
    term.keys("S")
    wait_for(lambda: term.jog_rows()["Z"]["step"] == "0.01", "the default step again")


def test_plus_on_the_jog_z_row_raises_the_tcp_by_the_step(
    term: Terminal, client: ArmfleetClient
) -> None:
    before = settled_tcp(client, WORLD)
    term.select(len(JOINTS) + AXES.index("Z"))
    term.keys("+")
    after = jogged_tcp(client, WORLD, before)
    assert_tcp_went(before, after, [0, 0, 0.01])
    term.shows("elbow_joint", f"{client.state(WORLD).target[ELBOW]:.2f}")  # the ack's targets


def test_t_key_turns_jogs_into_the_tool_frame(term: Terminal, client: ArmfleetClient) -> None:
    """+Rz in the tool frame turns the tool about its own z axis, in place."""
    before = settled_tcp(client, WORLD)
    term.keys("t")
    try:
        wait_for(lambda: term.said("Jog: tool frame"), "the tool frame on screen")
        term.select(len(JOINTS) + AXES.index("Rz"))
        term.keys("+")
        after = jogged_tcp(client, WORLD, before)
        c, s = np.cos(0.05), np.sin(0.05)
        about_z = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        want = rotvec_matrix(before["target_tcp"][3:]) @ about_z  # R · Rz: the tool's own z
        assert rotvec_matrix(after["target_tcp"][3:]) == pytest.approx(want, abs=1e-6)
        assert rotvec_matrix(after["tcp"][3:]) == pytest.approx(want, abs=1e-3)
        assert tcp_moved(before, after) == pytest.approx([0, 0, 0], abs=5e-4)
        # the same key in the base frame turns about the base's z: another rotation
        base_turn = about_z @ rotvec_matrix(before["target_tcp"][3:])
        assert np.abs(base_turn - want).max() > 0.01
    finally:
        term.keys("t")
        wait_for(lambda: term.said("Jog: base frame"), "the base frame again")


def test_a_jog_out_of_reach_shows_the_servers_reason_on_the_status_line(
    term: Terminal, client: ArmfleetClient
) -> None:
    # stretched out flat away from the table (towards it: through it, a protective stop)
    client.set_targets(WORLD, {"shoulder_lift_joint": -3.1416, "elbow_joint": 0.0})
    stretched = client.state(WORLD).target
    outward = "-" if client.tcp(WORLD)["target_tcp"][0] < 0 else "+"
    term.select(len(JOINTS) + AXES.index("X"))
    term.keys(outward)
    wait_for(lambda: term.said("the arm's reach"), f"the refusal on screen:\n{term.screen()}")
    assert term.said(f"Jog {outward}X (base) failed: HTTP 422: body.step:")
    assert list(client.state(WORLD).target) == list(stretched)  # nothing moved
    assert "Connected to" in term.status()  # still running, still streaming


def test_q_key_quits(server: Server) -> None:
    term = start_terminal(server.url, f"quit-{id(server)}")
    try:
        wait_for(lambda: "Connected to" in term.status(), "the controller to connect", 30)
        term.keys("q")
        wait_for(lambda: "EXITED 0" in term.screen(), "the controller to exit with status 0")
    finally:
        term.tmux("kill-server")
