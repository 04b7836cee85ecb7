"""The browser page end to end: a real server, and Debian's Chromium driven by Playwright.

The first tests check what the page is built on (GET /, /v1/scene, the pose frames of
/v1/ws/view) with plain HTTP/WebSocket clients; the rest load the page in Chromium (software
WebGL) and use it as a person would: click its buttons, read what it shows, compare pixels.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import time

import httpx
import numpy as np
import pytest
from conftest import HOME, JOINTS, free_port, page_in, page_of, serve, wait_for
from jog_checks import assert_tcp_went, jogged_tcp, rotvec_matrix, settled_tcp
from PIL import Image
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from clients import ArmfleetClient
from clients.apps.jog import step_texts

try:
    from playwright.sync_api import expect
except ImportError:  # the `browser` fixture skips the page tests and says why
    expect = None

NWORLD = 4
# The page's servers have no cameras: the camera pane, which stays hidden then, is
# test_camera_page.py's subject. A CPU service builds its camera renderer when the page first
# asks GET /v1/cameras (importing MuJoCo Warp; SIGINT then waits for the build): 2.5 s of CPU
# a server, 7-19 s of wall at its stop, and a picture stream while a page shows a world.
NO_CAMERAS = ("--cameras", "wrist=off,overview=off")


class RestartableServer:
    """A module's server on a fixed port, which one test kills and starts again."""

    def __init__(self, tmp_path) -> None:
        self.tmp_path = tmp_path
        self.port = free_port()
        self._cm = None
        self.server = None

    def start(self) -> None:
        self._cm = serve(
            worlds=NWORLD, port=self.port, extra_args=NO_CAMERAS, log_dir=self.tmp_path
        )
        self.server = self._cm.__enter__()

    def stop(self) -> None:
        if self._cm is not None:
            cm, self._cm = self._cm, None
            cm.__exit__(None, None, None)

    @property
    def url(self) -> str:
        return self.server.url


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    holder = RestartableServer(tmp_path_factory.mktemp("page"))
    holder.start()
    yield holder
    holder.stop()


@pytest.fixture
def http(srv):
    with httpx.Client(base_url=srv.url, timeout=10) as client:
        client.post("/v1/sim/mode", json={"mode": "realtime"}).raise_for_status()
        client.post("/v1/reset").raise_for_status()
        yield client


def read_pose_frame(data: bytes) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray]:
    """Parse an AFP1 frame by the layout documented in service/core/streams/wire.py."""
    assert data[:4] == b"AFP1"
    hlen = int.from_bytes(data[4:8], "little")
    assert hlen % 4 == 0
    header = json.loads(data[8 : 8 + hlen])
    n, nbody, at = header["n"], header["nbody"], 8 + hlen
    worlds = np.frombuffer(data, "<i4", n, at)
    faults = np.frombuffer(data, "<i4", n, at + 4 * n)
    poses = np.frombuffer(data, "<f4", n * nbody * 7, at + 8 * n).reshape(n, nbody, 7)
    assert len(data) == at + 8 * n + poses.nbytes
    return header, worlds, faults, poses


# ----------------------------------------------------------------- what the page is built on


def test_page_and_its_files_are_served_by_the_service(http):
    page = http.get("/")
    assert page.status_code == 200 and "text/html" in page.headers["content-type"]
    assert 'type="importmap"' in page.text and "/web/js/main.js" in page.text
    for path in ("/web/js/main.js", "/web/vendor/three/three.module.js", "/web/style.css"):
        r = http.get(path)
        assert r.status_code == 200 and len(r.content) > 100, path
    assert "three.js authors" in http.get("/web/vendor/three/LICENSE").text
    assert http.get("/web/nope.js").status_code == 404


def test_scene_route_describes_the_model_and_is_in_the_openapi_schema(http):
    scene = http.get("/v1/scene").json()
    assert scene["nbody"] == len(scene["bodies"]) == 19
    assert {b["name"] for b in scene["bodies"]} >= {"world", "pedestal", "cube", "gripper_base"}
    assert len(scene["geoms"]) > 20
    spec = http.get("/openapi.json").json()
    assert "/v1/scene" in spec["paths"] and "SceneGeom" in spec["components"]["schemas"]


def test_view_socket_sends_pose_frames_with_the_focus_worlds_state(srv, http):
    http.post("/v1/sim/pause").raise_for_status()
    http.put("/v1/worlds/2/targets", json={"name": ["elbow_joint"], "position": [1.0]})
    http.post("/v1/sim/step", json={"ticks": 30}).raise_for_status()
    state = http.get("/v1/worlds/2/state").json()
    scene = http.get("/v1/scene").json()
    nbody = scene["nbody"]
    gripper = next(b["id"] for b in scene["bodies"] if b["name"] == "gripper_base")
    url = f"{srv.server.ws_url}/v1/ws/view?worlds=0-3&focus=2&rate=30"
    with connect(url, compression="deflate") as ws:  # offered, as browsers do; declined
        assert "permessage-deflate" not in str(ws.response.headers)
        header, worlds, faults, poses = read_pose_frame(ws.recv(timeout=5))
        # Commands go over the same socket, with ids, and are acknowledged.
        ws.send(json.dumps({"op": "increment", "world": 1, "joint": 0, "delta": 0.1, "id": 7}))
        ack = json.loads(ws.recv(timeout=5))
    assert ack["op"] == "ack" and ack["id"] == 7 and ack["target"][0] == pytest.approx(0.1)
    assert header["op"] == "poses" and header["tick"] == state["tick"]
    assert header["n"] == 4 and header["nbody"] == nbody and header["stats"]["mode"] == "paused"
    assert header["focus"]["world"] == 2 and header["focus"]["name"] == JOINTS
    assert header["focus"]["target"][2] == pytest.approx(1.0)
    assert header["focus"]["position"] == pytest.approx(state["position"], abs=1e-6)
    assert worlds.tolist() == [0, 1, 2, 3] and faults.tolist() == [0, 0, 0, 0]
    np.testing.assert_allclose(np.linalg.norm(poses[..., 3:], axis=2), 1.0, atol=1e-5)
    np.testing.assert_array_equal(poses[:, 0], np.tile([0, 0, 0, 1, 0, 0, 0], (4, 1)))
    # World 2 bent its elbow, the others are at home: only its arm is elsewhere.
    assert np.linalg.norm(poses[2, gripper, :3] - poses[0, gripper, :3]) > 0.05
    np.testing.assert_allclose(poses[1], poses[0], atol=1e-6)


def test_view_socket_sends_a_heartbeat_while_still_and_every_frame_while_moving(srv, http):
    def frames_during(ws, seconds: float, between=None) -> int:
        n, end = 0, time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            if between:
                between()
            with contextlib.suppress(TimeoutError):
                ws.recv(timeout=min(left, 0.2))
                n += 1
        return n

    swing = iter(np.tile([0.3, -0.3], 100))

    def move() -> None:
        body = {"name": ["shoulder_pan_joint"], "position": [float(next(swing))]}
        http.put("/v1/worlds/1/targets", json=body).raise_for_status()

    time.sleep(1.0)  # let the reset arms come to rest
    with connect(f"{srv.server.ws_url}/v1/ws/view?worlds=0-3&focus=0&rate=30") as ws:
        ws.recv(timeout=5)  # the current state, at once
        still = frames_during(ws, 2.0)
        moving = frames_during(ws, 2.0, between=move)
    assert 2 <= still <= 8, still  # a heartbeat every 0.5 s, not 30 a second
    assert moving > 2 * still, (moving, still)


@pytest.mark.parametrize(
    ("query", "needle"),
    [("worlds=0-9", "do not exist (0..3)"), ("focus=7", "world 7 does not exist"), ("", "give")],
)
def test_view_socket_refuses_what_does_not_exist_with_a_reason(srv, query, needle):
    with (
        connect(f"{srv.server.ws_url}/v1/ws/view?{query}") as ws,
        pytest.raises(ConnectionClosed) as closed,
    ):
        ws.recv(timeout=5)
    assert closed.value.rcvd.code == 1008 and needle in closed.value.rcvd.reason


# ------------------------------------------------------------------- the page in Chromium


@pytest.fixture
def page(page_context):
    with page_in(page_context) as page:
        yield page


def open_page(page, srv, query: str) -> None:
    """Load the page and wait until it has drawn a streamed frame."""
    page.goto(f"{srv.url}/{query}")
    page.wait_for_function(
        "window.armfleet && window.armfleet.connected && window.armfleet.renders > 0",
        timeout=30_000,
    )


def reconnected(page) -> None:
    """Until the socket of the view the page just switched to is open: a key pressed before
    is not sent ("not connected: command not sent"; the page queues nothing)."""
    page.wait_for_function("window.armfleet.connected", timeout=30_000)


def wait_still(page, quiet_s: float = 1.0) -> None:
    """Until the page has drawn nothing new for `quiet_s` (the arm came to rest)."""
    last, since = -1, time.monotonic()
    deadline = since + 20
    while time.monotonic() - since < quiet_s:
        renders = page.evaluate("window.armfleet.renders")
        if renders != last:
            last, since = renders, time.monotonic()
        assert time.monotonic() < deadline, "the page kept redrawing"
        time.sleep(0.1)


def canvas_pixels(page) -> np.ndarray:
    png = page.locator("#view").screenshot()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def target(http, world: int) -> list[float]:
    return http.get(f"/v1/worlds/{world}/state").json()["target"]


def test_up_on_shoulder_pan_adds_a_tenth_and_down_on_a_closed_gripper_stays_at_zero(
    srv, http, page
):
    open_page(page, srv, "?world=0")
    before = target(http, 0)
    pan = page.locator('tr[data-joint="shoulder_pan_joint"]')
    pan.get_by_role("button", name="Up (+0.1)").click()
    after = wait_for(lambda: (t := target(http, 0))[0] != before[0] and t, "world 0's target")
    assert after[0] == pytest.approx(before[0] + 0.1)
    assert after[1:] == pytest.approx(before[1:])
    expect(pan.locator(".target")).to_have_text("0.10")  # the ack's target, shown at once

    finger = page.locator('tr[data-joint="finger_joint"]')
    finger.get_by_role("button", name="Down (-0.1)").click()
    expect(page.locator("#message")).to_contain_text("finger_joint")  # the ack said: clamped
    assert target(http, 0)[6] == 0.0
    expect(finger.locator(".target")).to_have_text("0.00")


def test_the_canvas_changes_when_the_arm_moves_and_not_while_it_is_still(srv, http, page):
    open_page(page, srv, "?world=1")
    wait_still(page)
    still = canvas_pixels(page)
    time.sleep(1.0)
    assert np.array_equal(canvas_pixels(page), still), "the view changed with nothing moving"

    move = {"name": ["shoulder_pan_joint", "elbow_joint"], "position": [1.2, 0.6]}
    http.put("/v1/worlds/1/targets", json=move).raise_for_status()
    wait_for(
        lambda: abs(http.get("/v1/worlds/1/state").json()["position"][0] - 1.2) < 0.02,
        "the arm to reach its new pose",
    )
    wait_still(page)
    moved = canvas_pixels(page)
    changed = np.abs(moved - still).sum(axis=2) > 30
    assert changed.mean() > 0.01, f"only {changed.mean():.4f} of the pixels changed"
    measured = page.locator('tr[data-joint="shoulder_pan_joint"] .measured')
    expect(measured).to_have_text("1.20")


def test_fleet_view_shows_every_world_and_a_click_focuses_the_clicked_one(srv, http, page):
    open_page(page, srv, "?world=0")
    one_world_draws = page.evaluate("window.armfleet.drawCalls")
    open_page(page, srv, "?view=fleet")
    labels = page.locator(".wlabel")
    expect(labels).to_have_count(NWORLD)
    assert [labels.nth(i).inner_text() for i in range(NWORLD)] == [str(w) for w in range(NWORLD)]
    # Instancing: the fleet costs the same draws per frame as one world (one per geom).
    assert page.evaluate("window.armfleet.drawCalls") == one_world_draws > 20
    page.locator('.wlabel[data-world="3"]').click()
    expect(page.locator("#world")).to_have_value("3")
    expect(page.locator('.wlabel[data-world="3"]')).to_have_class(re.compile(r"\bfocus\b"))
    expect(page.locator("#status")).to_contain_text("world 3", timeout=10_000)
    assert "world=3" in page.url and "view=fleet" in page.url
    # The focused world is the one the panel drives.
    elbow = page.locator('tr[data-joint="elbow_joint"]')
    elbow.get_by_role("button", name="Up (+0.1)").click()
    wait_for(lambda: target(http, 3)[2] == pytest.approx(HOME[2] + 0.1), "world 3's elbow")
    assert target(http, 0)[2] == pytest.approx(HOME[2])
    expect(labels).to_have_count(NWORLD)  # the layout stays while the focus moves


def test_the_fleet_view_shows_at_most_256_worlds(browser, tmp_path):
    """The browser guide's "up to 256 worlds", on 257 (a paused native server of its own: no
    tick runs): the page's grid holds worlds 0-255, and the view socket refuses a 257th,
    naming the limit."""
    extra = ("--engine", "mujoco", *NO_CAMERAS)
    with serve(worlds=257, mode="paused", extra_args=extra, log_dir=tmp_path) as big:
        with (
            connect(f"{big.ws_url}/v1/ws/view?worlds=0-256") as ws,
            pytest.raises(ConnectionClosed) as closed,
        ):
            ws.recv(timeout=5)
        assert closed.value.rcvd.code == 1008
        assert "257 asked, at most 256" in closed.value.rcvd.reason
        with page_of(browser, width=1000, height=640) as page:
            open_page(page, big, "?view=fleet")
            labels = page.locator(".wlabel")
            expect(labels).to_have_count(256)
            shown = labels.evaluate_all("els => els.map(e => Number(e.dataset.world))")
            assert shown == list(range(256))


def test_a_world_that_does_not_exist_says_so(srv, page):
    page.goto(f"{srv.url}/?world=99")
    banner = page.locator("#banner")
    expect(banner).to_be_visible(timeout=15_000)
    expect(banner).to_contain_text("World 99 does not exist")
    expect(banner).to_contain_text(f"this service runs worlds 0–{NWORLD - 1}")
    expect(page.get_by_role("button", name="Up (+0.1)").first).to_be_disabled()


def test_gripper_buttons_keyboard_shortcuts_and_reset_drive_the_world(srv, http, page):
    open_page(page, srv, "?world=1")
    page.get_by_role("button", name="Close gripper").click()
    wait_for(lambda: target(http, 1)[6] == pytest.approx(0.7), "world 1's gripper to close")
    page.get_by_role("button", name="Open gripper").click()
    wait_for(lambda: target(http, 1)[6] == 0.0, "world 1's gripper to open")
    # 3 picks row [2] (elbow_joint); the arrow keys press its Up / Down.
    page.keyboard.press("3")
    expect(page.locator('tr[data-joint="elbow_joint"]')).to_have_class(re.compile("selected"))
    page.keyboard.press("ArrowUp")
    page.keyboard.press("ArrowUp")
    page.keyboard.press("ArrowDown")
    page.keyboard.press("ArrowUp")
    wait_for(lambda: target(http, 1)[2] == pytest.approx(HOME[2] + 0.2), "two net presses")
    page.keyboard.press("c")
    wait_for(lambda: target(http, 1)[6] == pytest.approx(0.7), "C to close the gripper")
    # the browser guide's other keys: O gripper, R reset, [ ] previous/next world, F the view
    page.keyboard.press("o")
    wait_for(lambda: target(http, 1)[6] == 0.0, "O to open the gripper")
    page.keyboard.press("r")
    wait_for(lambda: target(http, 1) == pytest.approx(HOME), "R to bring world 1 home")
    page.keyboard.press("]")
    page.wait_for_url(re.compile(r"world=2"))
    reconnected(page)
    page.keyboard.press("3")
    page.keyboard.press("ArrowUp")
    wait_for(lambda: target(http, 2)[2] == pytest.approx(HOME[2] + 0.1), "] to drive world 2")
    page.keyboard.press("[")
    page.wait_for_url(re.compile(r"world=1"))
    page.keyboard.press("f")
    page.wait_for_url(re.compile(r"view=fleet"))
    page.keyboard.press("f")
    page.wait_for_url(lambda url: "view=fleet" not in url)
    reconnected(page)
    http.post("/v1/worlds/2/reset").raise_for_status()
    page.keyboard.press("ArrowUp")
    wait_for(lambda: target(http, 1)[2] == pytest.approx(HOME[2] + 0.1), "keys on world 1 again")
    page.get_by_role("button", name="Reset").click()
    wait_for(lambda: target(http, 1) == pytest.approx(HOME), "Reset to bring world 1 home")
    assert target(http, 0) == pytest.approx(HOME)  # the other worlds saw nothing


def test_a_hidden_tab_stops_its_stream_and_resumes_when_shown(srv, page):
    """Headless Chromium never hides a tab, so the page is told the way a browser tells it:
    `visibilityState` reads "hidden" and `visibilitychange` fires (then the reverse)."""
    open_page(page, srv, "?world=0")

    def set_visibility(state: str) -> None:
        page.evaluate(
            """(state) => {
                const as = (value) => ({ value, configurable: true });
                Object.defineProperty(document, 'visibilityState', as(state));
                Object.defineProperty(document, 'hidden', as(state === 'hidden'));
                document.dispatchEvent(new Event('visibilitychange'));
            }""",
            state,
        )

    set_visibility("hidden")
    page.wait_for_function("!window.armfleet.connected")
    frames = page.evaluate("window.armfleet.frames")
    time.sleep(0.5)
    assert page.evaluate("window.armfleet.frames") == frames  # no frame while hidden
    expect(page.locator("#status")).to_contain_text("tab hidden")
    set_visibility("visible")
    page.wait_for_function(f"window.armfleet.connected && window.armfleet.frames > {frames}")


@pytest.fixture
def arm(srv, http):
    with ArmfleetClient(srv.url) as client:
        yield client


def test_jog_buttons_move_the_tcp_by_the_step_in_the_base_then_the_tool_frame(srv, arm, page):
    open_page(page, srv, "?world=1")
    jog = page.locator("#jog")
    expect(jog.get_by_role("button")).to_have_text(
        ["-X", "+X", "-Y", "+Y", "-Z", "+Z", "-Rx", "+Rx", "-Ry", "+Ry", "-Rz", "+Rz"]
    )
    expect(page.locator("#jogStep option")).to_have_text(step_texts())  # the controllers' presets
    expect(page.locator("#jogStep option:checked")).to_have_text("10 mm / 0.05 rad")
    expect(jog.get_by_label("base")).to_be_checked()
    before = settled_tcp(arm, 1)
    jog.get_by_role("button", name="+Z", exact=True).click()
    after = jogged_tcp(arm, 1, before)
    assert_tcp_went(before, after, [0, 0, 0.01])
    shown = page.locator('tr[data-joint="elbow_joint"] .target')
    expect(shown).to_have_text(f"{arm.state(1).target[2]:.2f}")  # the ack's targets

    # The tool frame and the finest step: +Z goes along the tool's own z (down, at home).
    jog.get_by_label("tool").check()
    page.locator("#jogStep").select_option(label="1 mm / 0.01 rad")
    tool_z = rotvec_matrix(after["target_tcp"][3:])[:, 2]
    assert tool_z[2] < -0.9
    jog.get_by_role("button", name="+Z", exact=True).click()
    tooled = jogged_tcp(arm, 1, after)
    assert_tcp_went(after, tooled, 0.001 * tool_z)
    assert arm.state(0).target == pytest.approx(HOME)  # the other worlds saw nothing


def test_a_jog_out_of_reach_shows_the_servers_reason(srv, arm, page):
    open_page(page, srv, "?world=3")
    # stretched out flat away from the table (towards it: through it, a protective stop)
    arm.set_targets(3, {"shoulder_lift_joint": -3.1416, "elbow_joint": 0.0})
    stretched = arm.state(3).target
    outward, inward = ("-X", "+X") if arm.tcp(3)["target_tcp"][0] < 0 else ("+X", "-X")
    page.locator("#jog").get_by_role("button", name=outward, exact=True).click()
    message = page.locator("#message")
    expect(message).to_contain_text(
        f"jog x {outward[0]}0.01 (base) refused: step: the step leaves the arm's reach"
    )
    assert list(arm.state(3).target) == list(stretched)  # nothing moved
    # a step back in is taken, and its ack clears the message
    page.locator("#jog").get_by_role("button", name=inward, exact=True).click()
    expect(message).to_have_text("")
    assert list(arm.state(3).target) != list(stretched)
    assert page.evaluate("window.armfleet.connected")


def test_a_killed_server_shows_disconnected_and_the_page_recovers_when_it_is_back(srv, page):
    """Last in the module: it replaces the module's server with a new one on the same port."""
    open_page(page, srv, "?world=2")
    status = page.locator("#status")
    srv.server.process.kill()
    srv.stop()
    expect(status).to_contain_text("disconnected", timeout=15_000)
    srv.start()
    expect(status).to_contain_text("connected · world 2", timeout=60_000)
    with httpx.Client(base_url=srv.url, timeout=10) as http:
        before = target(http, 2)
        wrist = page.locator('tr[data-joint="wrist_1_joint"]')
        wrist.get_by_role("button", name="Down (-0.1)").click()
        wait_for(lambda: target(http, 2)[3] == pytest.approx(before[3] - 0.1), "world 2's wrist_1")


def test_a_running_trajectory_shows_its_progress_and_cancel_stops_it(srv, http, page):
    arm = JOINTS[:6]
    goal = (np.array(HOME[:6]) + 0.3).tolist()
    body = {"joint_names": arm, "points": [{"positions": goal, "time_from_start": 20.0}]}
    started = http.post("/v1/worlds/2/trajectory", json=body)
    assert started.status_code == 200, started.text
    open_page(page, srv, "?world=2")
    box = page.locator("#trajectory")
    expect(box).to_be_visible()
    expect(page.locator("#trajText")).to_contain_text(f"#{started.json()['id']} ")
    wait_for(lambda: page.locator("#trajProgress").evaluate("p => p.value") > 0, "progress")
    box.get_by_role("button", name="Cancel").click()
    traj_id = started.json()["id"]
    expect(page.locator("#trajText")).to_have_text(f"#{traj_id} aborted: cancelled")
    expect(page.locator("#trajCancel")).to_be_hidden()
    status = http.get("/v1/worlds/2/trajectory").json()
    assert status["state"] == "aborted" and status["reason"] == "cancelled"
