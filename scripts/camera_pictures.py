"""Redraw docs/wrist_camera.png and docs/page_camera.png from a real service.

    .venv/bin/python scripts/camera_pictures.py

A 4-world realtime service with the wrist camera at 320x240: the wrist PNG is what
GET /v1/worlds/0/cameras/wrist returns at home; the page shot is headless Chromium showing
world 0 with its camera pane.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from clients.testing import headless, serve  # noqa: E402

DOCS = ROOT / "docs"


def main() -> None:
    extra = ("--cameras", "wrist=320x240,overview=320x240")
    with serve(worlds=4, extra_args=extra) as s:
        deadline = time.monotonic() + 300
        while not httpx.get(f"{s.url}/v1/cameras").json()["ready"]:
            if time.monotonic() > deadline:
                raise SystemExit("cameras not ready in 300 s")
            time.sleep(0.5)
        png = httpx.get(f"{s.url}/v1/worlds/0/cameras/wrist", params={"format": "png"})
        png.raise_for_status()
        (DOCS / "wrist_camera.png").write_bytes(png.content)
        from playwright.sync_api import sync_playwright

        with sync_playwright() as p:
            browser = headless.launch(p)
            page = browser.new_page(viewport={"width": 1280, "height": 820})
            page.goto(f"{s.url}/?world=0")
            page.wait_for_function(
                "window.armfleetCamera && window.armfleetCamera.pictures > 2", timeout=60_000
            )
            time.sleep(1.0)
            page.screenshot(path=str(DOCS / "page_camera.png"))
            browser.close()
    print(f"wrote {DOCS / 'wrist_camera.png'} and {DOCS / 'page_camera.png'}")


if __name__ == "__main__":
    main()
