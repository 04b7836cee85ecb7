"""The page's camera pane in Debian's Chromium (Playwright): it shows the focused world's wrist
camera live, follows the camera chosen, and stops asking in the fleet view."""

from __future__ import annotations

import io
import time

import numpy as np
import pytest
from PIL import Image

from clients.testing import Server
from tests.conftest import cameras_ready, page_of


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Server:
    yield from cameras_ready(tmp_path_factory, "p")


@pytest.fixture
def page(server: Server, browser):
    with page_of(browser, width=1000, height=900) as page:
        yield page


def _pictures(page) -> int:
    return page.evaluate("window.armfleetCamera.pictures")


def test_camera_pane_shows_the_wrist_camera_of_the_world_in_view(server: Server, page) -> None:
    page.goto(f"{server.url}/?world=2")
    page.wait_for_function(
        "window.armfleetCamera && window.armfleetCamera.pictures > 3", timeout=60_000
    )
    assert page.evaluate("window.armfleetCamera.camera") == "wrist"
    caption = page.locator("#camera figcaption").inner_text()
    assert caption.startswith("wrist · world 2 · tick")
    # What Chromium shows is the service's picture: the red cube between the fingers.
    shown = np.asarray(
        Image.open(io.BytesIO(page.locator("#camera img").screenshot())).convert("RGB")
    )
    r, g, b = (shown[..., i].astype(int) for i in range(3))
    cube = (r > 60) & (r > 1.8 * g) & (r > 1.8 * b)
    assert cube.mean() > 0.01, "no cube-red pixels in the pane"
    ys, xs = np.nonzero(cube)
    h, w = cube.shape
    assert abs(xs.mean() / w - 0.5) < 0.2 and abs(ys.mean() / h - 0.5) < 0.3  # near the middle

    page.select_option("#camera select", "overview")
    page.wait_for_function("window.armfleetCamera.camera === 'overview'", timeout=30_000)

    page.keyboard.press("f")  # fleet view: the pane stops asking for pictures
    time.sleep(1.0)
    before = _pictures(page)
    time.sleep(1.5)
    assert _pictures(page) <= before + 1
