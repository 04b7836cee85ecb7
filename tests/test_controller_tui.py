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

import pytest
from conftest import ELBOW, FINGER, HOME, JOINTS, ROOT, Server, target_after, wait_for

from clients import ArmfleetClient

if shutil.which("tmux") is None:
    pytest.skip("tmux is not installed (apt-get install tmux)", allow_module_level=True)

WORLD = 2
ROW = re.compile(r"^\s*(>?)\s*\[(\d)\] (\w+)\s+(-?\d+\.\d\d|--)\s+(-?\d+\.\d\d|--)\s*$")


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

    def status(self) -> str:
        return next((ln for ln in self.screen().splitlines() if "http://" in ln), "")

    def selected(self) -> int:
        return next(r["index"] for r in self.rows().values() if r["selected"])

    def select(self, joint: int) -> None:
        """Move the row cursor to `joint` with j/k, as a user would."""
        step = joint - self.selected()
        self.keys(*(["j"] * step if step > 0 else ["k"] * -step))
        wait_for(lambda: self.selected() == joint, f"row {joint} to be selected")

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


def test_q_key_quits(server: Server) -> None:
    term = start_terminal(server.url, f"quit-{id(server)}")
    try:
        wait_for(lambda: "Connected to" in term.status(), "the controller to connect", 30)
        term.keys("q")
        wait_for(lambda: "EXITED 0" in term.screen(), "the controller to exit with status 0")
    finally:
        term.tmux("kill-server")
