#!/usr/bin/env python3
"""Screenshots of the browser page for the README, taken from the real page in headless Chromium.

    .venv/bin/python scripts/page_screenshots.py      # writes docs/page_world.png, page_fleet.png

Starts its own 16-world service on a free loopback port, gives the worlds different poses (and
world 0 a grasp-ready one), opens the page's world view and fleet view, and saves both.
"""

from __future__ import annotations

import contextlib
import math
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
from playwright.sync_api import sync_playwright

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from clients.testing import headless  # noqa: E402

DOCS = ROOT / "docs"
NWORLD = 16


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def service(port: int):
    cmd = [sys.executable, "-m", "service.cli", "serve", "--worlds", str(NWORLD)]
    proc = subprocess.Popen([*cmd, "--port", str(port)], cwd=ROOT)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 300
        while True:
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{url}/readyz", timeout=1).status_code == 200:
                    break
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("the service did not start")
            time.sleep(0.3)
        yield url
    finally:
        proc.send_signal(2)
        proc.wait(timeout=20)


def pose_worlds(url: str) -> None:
    """A different, plausible pose per world so the fleet view shows a fleet, not one arm."""
    home = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0, 0.0]
    rows = []
    for w in range(NWORLD):
        t = list(home)
        t[0] = 0.6 * math.sin(1.7 * w)
        t[1] = -1.57 - 0.35 * abs(math.sin(0.9 * w + 1))  # raised: clear of the table
        t[2] = 1.57 - 0.4 * abs(math.cos(1.3 * w))
        t[6] = 0.7 * (w % 3) / 2
        rows.append(t)
    rows[0] = [0.3, -1.45, 1.45, -1.57, -1.57, 0.0, 0.35]
    body = {"worlds": list(range(NWORLD)), "position": rows}
    httpx.post(f"{url}/v1/targets", json=body, timeout=10).raise_for_status()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # until every arm got there
        states = httpx.get(f"{url}/v1/worlds/state", timeout=10).json()["worlds"]
        gaps = [abs(p - t) for s in states for p, t in zip(s["position"], s["target"], strict=True)]
        if max(gaps) < 0.02:
            break
        time.sleep(0.3)


def main() -> int:
    reason = headless.why_unavailable()
    if reason:
        print(reason, file=sys.stderr)
        return 1
    DOCS.mkdir(exist_ok=True)
    with service(free_port()) as url, sync_playwright() as p:
        pose_worlds(url)
        browser = headless.launch(p)
        page = browser.new_page(viewport={"width": 1280, "height": 720})
        shots = (("?world=0", "page_world.png"), ("?world=5&view=fleet", "page_fleet.png"))
        for query, name in shots:
            page.goto(f"{url}/{query}")
            page.wait_for_function("window.armfleet && window.armfleet.renders > 0", timeout=60_000)
            time.sleep(1.5)  # a few frames in: the status line shows the measured speed
            page.screenshot(path=str(DOCS / name))
            print(f"wrote {DOCS / name}")
        browser.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
