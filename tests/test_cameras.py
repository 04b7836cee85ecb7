"""Cameras end to end: a real `armfleet serve` renders, Pillow decodes, MuJoCo checks the pixels.

The judges are outside the service: MuJoCo itself (mj_forward's cam_xpos / cam_xmat, the
model's fovy, mj_ray's distance) says where the cube must appear and how far it is; Pillow
decodes every PNG and JPEG. The servers are paused, so a picture shows a known state.
"""

from __future__ import annotations

import concurrent.futures
import io
import math
import subprocess
import sys
import threading

import httpx
import mujoco
import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

import service.app
import service.cli
from clients.testing import Server, serve
from clients.wire import unpack_images as unpack
from service.core.cameras.feed import rows_of
from service.core.sim.robot import load_robot
from tests.conftest import ROOT, cameras_warmed

ROBOT = load_robot()
MJM = ROBOT.mjm
CUBE = mujoco.mj_name2id(MJM, mujoco.mjtObj.mjOBJ_BODY, "cube")
GROUPS = np.array([1, 1, 1, 0, 0, 0], dtype=np.uint8)  # the geom groups the renderer draws


@pytest.fixture(scope="module")
def warp_server(tmp_path_factory: pytest.TempPathFactory) -> Server:
    extra = ("--engine", "warp", "--cameras", "wrist=160x120:rgb+depth+seg")
    with serve(
        worlds=4, mode="paused", extra_args=extra, log_dir=tmp_path_factory.mktemp("w")
    ) as s:
        yield s


@pytest.fixture(scope="module")
def http(warp_server: Server) -> httpx.Client:
    cameras_warmed(warp_server.url)  # they warm up beside a ready service
    with httpx.Client(base_url=warp_server.url, timeout=60) as c:
        yield c


def _home() -> mujoco.MjData:
    d = mujoco.MjData(MJM)
    mujoco.mj_resetDataKeyframe(MJM, d, ROBOT.home_key)
    mujoco.mj_forward(MJM, d)
    return d


def _camera(http: httpx.Client, name: str) -> dict:
    return next(c for c in http.get("/v1/cameras").json()["cameras"] if c["name"] == name)


def _rgb(http: httpx.Client, world: int, name: str, **params: str) -> np.ndarray:
    r = http.get(f"/v1/worlds/{world}/cameras/{name}", params=params)
    assert r.status_code == 200, r.text
    return np.asarray(Image.open(io.BytesIO(r.content)).convert("RGB"))


def _depth(http: httpx.Client, world: int, name: str) -> np.ndarray:
    r = http.get(f"/v1/worlds/{world}/cameras/{name}", params={"image": "depth", "format": "raw"})
    assert r.status_code == 200, r.text
    cam = _camera(http, name)
    return np.frombuffer(r.content, "<f4").reshape(cam["height"], cam["width"])


def _project(d: mujoco.MjData, cam_id: int, cam: dict, point: np.ndarray) -> tuple[float, float]:
    """Pixel (u, v) of a world point, from MuJoCo's camera pose and the model's fovy alone."""
    local = d.cam_xmat[cam_id].reshape(3, 3).T @ (point - d.cam_xpos[cam_id])
    f = 0.5 * cam["height"] / math.tan(math.radians(MJM.cam_fovy[cam_id]) / 2)
    u = (cam["width"] - 1) / 2 + f * local[0] / -local[2]
    v = (cam["height"] - 1) / 2 - f * local[1] / -local[2]
    return u, v


def _is_cube(pixel: np.ndarray) -> bool:
    r, g, b = (int(x) for x in pixel)
    return r > 60 and r > 1.8 * g and r > 1.8 * b  # the cube is red; table, floor, arm are not


def _check_cube_seen(http: httpx.Client, d: mujoco.MjData, name: str, world: int = 0) -> None:
    cam = _camera(http, name)
    cid = mujoco.mj_name2id(MJM, mujoco.mjtObj.mjOBJ_CAMERA, name)
    u, v = _project(d, cid, cam, d.xpos[CUBE])
    px, py = round(u), round(v)
    assert 0 <= px < cam["width"] and 0 <= py < cam["height"], (u, v)
    rgb = _rgb(http, world, name)
    assert _is_cube(rgb[py, px]), f"{name}: pixel ({px}, {py}) is {rgb[py, px]}, not the cube"
    # Depth there: MuJoCo's own ray through that pixel's centre, projected on the optical axis.
    f = cam["K"][0]
    ray_cam = np.array([(px - cam["K"][2]) / f, -(py - cam["K"][5]) / f, -1.0])
    ray_cam /= np.linalg.norm(ray_cam)
    ray = d.cam_xmat[cid].reshape(3, 3) @ ray_cam
    geom = np.zeros(1, dtype=np.int32)
    dist = mujoco.mj_ray(MJM, d, d.cam_xpos[cid], ray, GROUPS, 1, -1, geom)
    assert mujoco.mj_id2name(MJM, mujoco.mjtObj.mjOBJ_GEOM, int(geom[0])) == "cube_geom"
    depth = _depth(http, world, name)[py, px]
    assert depth == pytest.approx(dist * -ray_cam[2], rel=0.01)


def test_cameras_list_the_scene_cameras_with_k_from_fovy_and_size(http: httpx.Client) -> None:
    cams = {c["name"]: c for c in http.get("/v1/cameras").json()["cameras"]}
    assert set(cams) == {"wrist", "overview"}
    assert (cams["wrist"]["width"], cams["wrist"]["height"]) == (160, 120)  # --cameras
    assert (cams["overview"]["width"], cams["overview"]["height"]) == (128, 96)  # the default
    assert cams["wrist"]["outputs"] == ["rgb", "depth", "seg"]
    assert cams["overview"]["outputs"] == ["rgb", "depth"]
    for name, c in cams.items():
        cid = mujoco.mj_name2id(MJM, mujoco.mjtObj.mjOBJ_CAMERA, name)
        assert c["fovy"] == pytest.approx(MJM.cam_fovy[cid])
        f = c["height"] / 2 / math.tan(math.radians(MJM.cam_fovy[cid]) / 2)
        k = np.array(c["K"]).reshape(3, 3)
        assert k == pytest.approx(
            np.array([[f, 0, (c["width"] - 1) / 2], [0, f, (c["height"] - 1) / 2], [0, 0, 1]])
        )


def test_nobody_looking_draws_nothing(warp_server: Server) -> None:
    # A fresh module server: before any image is asked, no render has run.
    text = httpx.get(f"{warp_server.url}/metrics").text
    line = next(x for x in text.splitlines() if x.startswith("armfleet_camera_renders_total"))
    assert float(line.split()[1]) == 0.0


@pytest.mark.parametrize("name", ["wrist", "overview"])
def test_cube_centre_lands_on_cube_pixels_and_depth_is_mj_ray(
    http: httpx.Client, name: str
) -> None:
    _check_cube_seen(http, _home(), name)


def test_native_engine_draws_the_same_pixels_for_the_same_state(
    http: httpx.Client, tmp_path_factory: pytest.TempPathFactory
) -> None:
    extra = ("--engine", "mujoco", "--cameras", "wrist=160x120:rgb+depth+seg")
    with serve(
        worlds=2, mode="paused", extra_args=extra, log_dir=tmp_path_factory.mktemp("n")
    ) as s:
        # The cameras guide: on the CPU the renderer is built at the first ask, and a picture
        # asked before it is ready waits for the build, drawn from the tick it asked for.
        url = f"{s.url}/v1/worlds/0/cameras/wrist"
        first = httpx.get(url, params={"format": "raw"}, timeout=300)
        assert first.status_code == 200 and first.headers["x-armfleet-tick"] == "0", first.text
        assert httpx.get(f"{s.url}/v1/cameras", timeout=60).json()["ready"] is True
        native = first.content
        overview = httpx.get(f"{s.url}/v1/worlds/1/cameras/overview", params={"format": "raw"})
    warp_reply = http.get("/v1/worlds/0/cameras/wrist", params={"format": "raw"})
    assert warp_reply.headers["x-armfleet-tick"] == "0"  # runs before the arm-moving test
    warp = warp_reply.content
    assert native == warp  # home in both: bit-identical images
    warp_overview = http.get("/v1/worlds/2/cameras/overview", params={"format": "raw"})
    assert overview.content == warp_overview.content


def test_moving_the_arm_moves_the_wrist_image(http: httpx.Client) -> None:
    before = _rgb(http, 1, "wrist")
    joints = ["shoulder_pan_joint", "wrist_1_joint"]
    r = http.put("/v1/worlds/1/targets", json={"name": joints, "position": [0.15, -1.45]})
    assert r.status_code == 200, r.text
    assert http.post("/v1/sim/step", json={"ticks": 120}).status_code == 200
    after = _rgb(http, 1, "wrist")
    assert np.abs(after.astype(int) - before.astype(int)).mean() > 5  # the view changed
    # ... and where the cube is now is where MuJoCo puts it for the arm's measured joints.
    state = http.get("/v1/worlds/1/state").json()
    d = _home()
    for joint, q in zip(state["name"], state["position"], strict=True):
        if joint != "finger_joint":
            d.qpos[MJM.jnt_qposadr[mujoco.mj_name2id(MJM, mujoco.mjtObj.mjOBJ_JOINT, joint)]] = q
    mujoco.mj_forward(MJM, d)
    _check_cube_seen(http, d, "wrist", world=1)
    # A world nobody moved still shows home.
    assert np.array_equal(_rgb(http, 0, "wrist"), _rgb(http, 2, "wrist"))


def test_formats_decode_in_pillow(http: httpx.Client) -> None:
    jpeg = http.get("/v1/worlds/0/cameras/overview", headers={"Accept": "image/jpeg"})
    assert jpeg.headers["content-type"] == "image/jpeg"
    assert Image.open(io.BytesIO(jpeg.content)).format == "JPEG"
    assert int(jpeg.headers["x-armfleet-tick"]) >= 0
    depth = http.get("/v1/worlds/0/cameras/wrist", params={"image": "depth"})
    pic = Image.open(io.BytesIO(depth.content))
    assert pic.mode.startswith("I;16") and pic.size == (160, 120)
    mm = np.asarray(pic, dtype=np.float64)
    metres = _depth(http, 0, "wrist")
    assert np.abs(mm / 1000 - metres).max() <= 0.0005 + 1e-6  # millimetres, rounded
    seg = http.get("/v1/worlds/0/cameras/wrist", params={"image": "seg", "format": "raw"})
    ids = np.frombuffer(seg.content, "<i4").reshape(120, 160)
    u, v = _project(_home(), 1, _camera(http, "wrist"), _home().xpos[CUBE])
    assert MJM.geom(int(ids[round(v), round(u)])).name == "cube_geom"


def test_jpeg_quality_defaults_to_90_and_replies_say_their_tick_and_size(
    http: httpx.Client,
) -> None:
    url = "/v1/worlds/0/cameras/overview"  # not in --cameras: the default size, 128x96
    plain = http.get(url, params={"format": "jpeg"})
    ninety = http.get(url, params={"format": "jpeg", "quality": 90})
    low = http.get(url, params={"format": "jpeg", "quality": 10})
    assert plain.headers["x-armfleet-tick"] == ninety.headers["x-armfleet-tick"]  # paused
    assert plain.content == ninety.content and len(low.content) < len(plain.content)
    assert plain.headers["x-armfleet-size"] == "128x96"
    wrist = http.get("/v1/worlds/0/cameras/wrist", params={"image": "depth", "format": "raw"})
    assert wrist.headers["x-armfleet-size"] == "160x120"
    assert len(wrist.content) == 160 * 120 * 4  # float32 metres


def test_many_worlds_in_one_binary_reply(http: httpx.Client) -> None:
    r = http.get("/v1/cameras/wrist/images", params={"worlds": "0-3", "format": "png"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-armfleet-images"
    header, images = unpack(r.content)
    assert header["worlds"] == [0, 1, 2, 3] and header["camera"] == "wrist"
    pics = [np.asarray(Image.open(io.BytesIO(b))) for b in images]
    assert all(p.shape == (120, 160, 3) for p in pics)
    assert np.array_equal(pics[0], _rgb(http, 0, "wrist"))  # paused: the same tick


def test_requests_at_once_each_get_their_own_worlds(
    warp_server: Server, http: httpx.Client
) -> None:
    """Requests for one camera that meet at a tick boundary are drawn in one render; each must
    still get exactly its own worlds (raw, so bytes compare exactly)."""
    asks = ["3,1", "0-3", "2", "1-2", "0", "3,0", "1", "2-3"] * 2
    alone = {w: _rgb(http, w, "wrist", format="png") for w in range(4)}
    barrier = threading.Barrier(len(asks))

    def ask(worlds: str) -> tuple[dict, list[bytes]]:
        with httpx.Client(base_url=warp_server.url, timeout=60) as c:
            barrier.wait()
            params = {"worlds": worlds, "format": "raw"}
            return unpack(c.get("/v1/cameras/wrist/images", params=params).content)

    with concurrent.futures.ThreadPoolExecutor(len(asks)) as pool:
        answers = list(pool.map(ask, asks))
    for worlds, (header, images) in zip(asks, answers, strict=True):
        ends = [int(x) for x in worlds.replace("-", ",").split(",")]
        want = list(range(ends[0], ends[1] + 1)) if "-" in worlds else sorted(ends)
        assert header["worlds"] == want  # a world list is served in ascending order
        for w, raw in zip(want, images, strict=True):
            got = np.frombuffer(raw, np.uint8).reshape(120, 160, 3)
            assert np.array_equal(got, alone[w]), (worlds, w)


def test_rows_of_a_request_among_the_drawn_worlds() -> None:
    drawn = np.array([0, 2, 3, 5, 9])
    assert rows_of(drawn, np.array([2, 3, 5])) == slice(1, 4)  # a run: a view, no copy
    assert list(rows_of(drawn, np.array([5, 0]))) == [3, 0]
    assert list(rows_of(drawn, np.array([0, 3]))) == [0, 2]


@pytest.mark.parametrize(
    ("path", "params", "status", "named"),
    [
        ("/v1/worlds/9/cameras/wrist", {}, 404, "world 9"),
        ("/v1/worlds/0/cameras/nose", {}, 404, "'nose'"),
        ("/v1/worlds/0/cameras/wrist", {"image": "heat"}, 422, "image"),
        ("/v1/worlds/0/cameras/overview", {"image": "seg"}, 409, "seg"),
        ("/v1/worlds/0/cameras/wrist", {"quality": "0"}, 422, "quality"),
        ("/v1/worlds/0/cameras/wrist", {"quality": "101"}, 422, "quality"),
        ("/v1/cameras/wrist/images", {"worlds": "0-9"}, 404, "0-9"),
        ("/v1/cameras/wrist/images", {"worlds": "a"}, 422, "worlds"),
    ],
)
def test_bad_requests_name_the_field(
    http: httpx.Client, path: str, params: dict, status: int, named: str
) -> None:
    r = http.get(path, params=params)
    assert r.status_code == status, r.text
    assert named in r.text


def test_depth_asked_as_jpeg_comes_as_16_bit_png(http: httpx.Client) -> None:
    """JPEG cannot hold millimetres: the pair the schema allows is served as PNG, and says so."""
    r = http.get("/v1/worlds/0/cameras/wrist", params={"image": "depth", "format": "jpeg"})
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    assert Image.open(io.BytesIO(r.content)).mode in ("I", "I;16")


def test_render_metrics_count(http: httpx.Client) -> None:
    _rgb(http, 0, "overview")
    text = http.get("/metrics").text
    got = {
        x.split()[0]: float(x.split()[1])
        for x in text.splitlines()
        if x.startswith("armfleet_camera")
    }
    assert got["armfleet_camera_renders_total"] >= 1
    assert got["armfleet_camera_images_total"] >= got["armfleet_camera_renders_total"]
    assert got["armfleet_camera_render_seconds_total"] > 0


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--cameras", "nose=off"], "no camera 'nose'"),
        (["--camera-size", "0x96"], "camera_size"),
        (["--camera-outputs", "rgb,heat"], "camera_outputs"),
        (["--cameras", "wrist=64x48:rgb+x"], "cameras.wrist"),
        (["--camera-size", "4096x4096"], "camera_batch"),
        (["--camera-device", "gpu"], "camera_device"),
    ],
)
def test_bad_camera_settings_are_refused_at_start(
    args: list[str], named: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`armfleet serve`'s own command, run in this process: the settings refuse these before
    anything is built (a process each cost ~2 CPU-s of imports; the last case below runs the
    real process). Nothing may be built: building the service here fails the test."""

    def create_app(settings: object) -> None:
        raise AssertionError(f"{args}: the service was built, the settings let it through")

    monkeypatch.setattr(service.app, "create_app", create_app)
    done = CliRunner().invoke(service.cli.app, ["serve", "--port", "0", *args])
    assert done.exit_code == 2 and isinstance(done.exception, SystemExit), done.output
    assert named in done.stderr and not done.stdout


def test_a_missing_cuda_device_for_the_cameras_is_refused_at_start() -> None:
    """Checked as the service is created (Warp counts the devices), in a real `armfleet serve`
    process: exit 2, one line naming the setting, no traceback."""
    args = ["--camera-device", "cuda:64"]
    cmd = [sys.executable, "-m", "service.cli", "serve", "--port", "0", *args]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 2
    assert "no CUDA device 'cuda:64'" in done.stderr and "Traceback" not in done.stderr


def test_cameras_do_not_change_the_physics() -> None:
    """The scene with its cameras steps bit for bit as the same scene without them."""
    spec = mujoco.MjSpec.from_file(str(ROOT / "mjcf" / "scene.xml"))
    for cam in list(spec.cameras):
        spec.delete(cam)
    bare = spec.compile()
    assert bare.ncam == 0 and MJM.ncam == 2
    runs = []
    for model in (MJM, bare):
        d = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, d, ROBOT.home_key)
        d.ctrl[:] = [0.3, -1.3, 1.4, -1.6, -1.5, 0.2, 0.5]  # the arm moves, the gripper closes
        for _ in range(500):
            mujoco.mj_step(model, d)
        runs.append(np.concatenate([d.qpos, d.qvel]))
    assert np.array_equal(runs[0], runs[1])
