"""Many viewers: headless Chromium pages watching a realtime service (the browser page's cost).

What is measured, on one realtime service of N worlds (64 by default):
* the loop's real-time factor with no viewer, with twenty socket-only viewers (Python clients
  reading the page's pose frames: what the *server* pays for viewers), and with twenty real
  pages in headless Chromium (fleet view of every world), arms still and arms moving;
* per page: pose frames delivered per second (the stream rate asked is 30) and frames drawn
  per second (the page draws only when something moved, at most once per display frame);
* page load: navigation start to the first drawn frame, at 1 world and at N.

Chromium renders WebGL in software here (SwiftShader) on the same cores as the service, so on a
small machine the pages' drawing competes with the simulation; the socket-only row separates
the server's own cost from that.
"""

from __future__ import annotations

import asyncio
import contextlib
import statistics
import threading
import time
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np

from bench.registry import Context, Result, section

PAGES = 20
RATE = 30.0  # pose frames per second each page asks for (the page's default)
VIEWPORT = {"width": 960, "height": 540}
HOME = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0, 0.0])


def _info(url: str) -> tuple[float, dict[str, Any]]:
    return time.perf_counter(), httpx.get(f"{url}/v1/info", timeout=10).json()


def _rtf(a: tuple[float, dict[str, Any]], b: tuple[float, dict[str, Any]]) -> float:
    ticks = b[1]["tick"] - a[1]["tick"]
    return round(ticks / b[1]["control_hz"] / (b[0] - a[0]), 3)


MOVING = 4  # arms that swing while "arms moving": enough that every page redraws every frame


@contextlib.contextmanager
def moving_arms(url: str, nworld: int, period: float = 0.1) -> Iterator[None]:
    """The first MOVING worlds' arms swing (pan and wrist_3, a 4 s sine, a phase each), clear of
    the table, so that every page has to draw every frame. Only a few move because a moving arm
    costs the solver ~3x a resting one (measured: 4.6 → 15 ms per tick at 16 worlds): moving
    all of them would measure the physics, not the viewers."""
    stop = threading.Event()
    movers = min(MOVING, nworld)
    phase = np.linspace(0, 2 * np.pi, movers, endpoint=False)

    def run() -> None:
        t0 = time.perf_counter()
        with httpx.Client(base_url=url, timeout=10) as http:
            while not stop.wait(period):
                s = np.sin(2 * np.pi * (time.perf_counter() - t0) / 4.0 + phase)
                pos = np.tile(HOME, (movers, 1))
                pos[:, 0] += 0.5 * s
                pos[:, 5] += 1.0 * s
                body = {"worlds": list(range(movers)), "position": pos.tolist()}
                with contextlib.suppress(httpx.HTTPError):
                    http.post("/v1/targets", json=body)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        httpx.post(f"{url}/v1/reset", timeout=10)


def rtf_alone(url: str, nworld: int, seconds: float, moving: bool) -> float:
    with moving_arms(url, nworld) if moving else contextlib.nullcontext():
        time.sleep(1.0)
        a = _info(url)
        time.sleep(seconds)
        return _rtf(a, _info(url))


def socket_viewers(url: str, nworld: int, viewers: int, seconds: float) -> dict[str, Any]:
    """`viewers` Python clients on the page's socket: the server's cost without any drawing."""
    import websockets

    ws_url = url.replace("http://", "ws://") + f"/v1/ws/view?worlds=0-{nworld - 1}&rate={RATE}"
    counts = [0] * viewers

    async def one(i: int, until: float) -> None:
        async with websockets.connect(ws_url, max_size=None) as ws:
            while time.perf_counter() < until:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(ws.recv(), timeout=0.5)
                    counts[i] += 1

    async def all_of_them() -> tuple[float, tuple[float, dict[str, Any]]]:
        warm = time.perf_counter() + 2.0
        until = warm + seconds
        tasks = [asyncio.create_task(one(i, until)) for i in range(viewers)]
        await asyncio.sleep(2.0)
        start_counts = list(counts)
        a = await asyncio.to_thread(_info, url)
        await asyncio.gather(*tasks)
        b = await asyncio.to_thread(_info, url)
        fps = [(c - s) / seconds for c, s in zip(counts, start_counts, strict=True)]
        return _rtf(a, b), fps

    rtf, fps = asyncio.run(all_of_them())
    return {"rtf": rtf, "frames_per_s": _spread(fps)}


def _spread(values: list[float]) -> dict[str, float]:
    return {
        "mean": round(statistics.fmean(values), 1),
        "min": round(min(values), 1),
        "max": round(max(values), 1),
    }


def _counters(pages: list[Any]) -> list[dict[str, Any]]:
    return [p.evaluate("({...window.armfleet})") for p in pages]


def chromium_viewers(
    url: str, nworld: int, pages: int, seconds: float, moving: bool, browser: Any
) -> dict[str, Any]:
    """`pages` real pages (fleet view of every world) in one headless Chromium."""
    context = browser.new_context(viewport=VIEWPORT)
    try:
        opened = []
        for _ in range(pages):
            page = context.new_page()
            page.goto(f"{url}/?view=fleet&worlds=0-{nworld - 1}&world=0&rate={RATE:g}")
            opened.append(page)
        first_draw = "window.armfleet && window.armfleet.renders > 0"
        for page in opened:
            page.wait_for_function(first_draw, timeout=120_000)
        load_ms = [c["firstRenderMs"] for c in _counters(opened)]
        with moving_arms(url, nworld) if moving else contextlib.nullcontext():
            time.sleep(2.0)
            c0, a = _counters(opened), _info(url)
            time.sleep(seconds)
            c1, b = _counters(opened), _info(url)
        dt = b[0] - a[0]
        frames = [(y["frames"] - x["frames"]) / dt for x, y in zip(c0, c1, strict=True)]
        draws = [(y["renders"] - x["renders"]) / dt for x, y in zip(c0, c1, strict=True)]
        return {
            "rtf": _rtf(a, b),
            "frames_per_s": _spread(frames),
            "draws_per_s": _spread(draws),
            "load_ms": _spread(load_ms),
        }
    finally:
        context.close()


def single_page(url: str, worlds: str, seconds: float, browser: Any, nworld: int) -> dict:
    """One page, arms moving: load time to the first drawn frame and frames drawn per second."""
    context = browser.new_context(viewport=VIEWPORT)
    try:
        page = context.new_page()
        t0 = time.perf_counter()
        page.goto(f"{url}/{worlds}")
        page.wait_for_function("window.armfleet && window.armfleet.renders > 0", timeout=120_000)
        wall_ms = (time.perf_counter() - t0) * 1e3
        with moving_arms(url, nworld):
            time.sleep(2.0)
            c0, a = _counters([page])[0], _info(url)
            time.sleep(seconds)
            c1, b = _counters([page])[0], _info(url)
        dt = b[0] - a[0]
        return {
            "load_ms": c1["firstRenderMs"],
            "load_wall_ms": round(wall_ms),
            "frames_per_s": round((c1["frames"] - c0["frames"]) / dt, 1),
            "draws_per_s": round((c1["renders"] - c0["renders"]) / dt, 1),
            "rtf": _rtf(a, b),
        }
    finally:
        context.close()


def measure(url: str, nworld: int, pages: int = PAGES, seconds: float = 10.0) -> dict[str, Any]:
    """Every measurement of this section against one running realtime service."""
    from playwright.sync_api import sync_playwright

    from clients.testing import headless

    out: dict[str, Any] = {"nworld": nworld, "pages": pages, "rate": RATE, "seconds": seconds}
    out["alone"] = {"rtf": rtf_alone(url, nworld, seconds, moving=False)}
    out["alone_moving"] = {"rtf": rtf_alone(url, nworld, seconds, moving=True)}
    with moving_arms(url, nworld):
        out["sockets"] = socket_viewers(url, nworld, pages, seconds)
    with sync_playwright() as p:
        browser = headless.launch(p)
        try:
            out["page_1_world"] = single_page(url, "?world=0", seconds, browser, nworld)
            fleet = f"?view=fleet&worlds=0-{nworld - 1}"
            out[f"page_{nworld}_worlds"] = single_page(url, fleet, seconds, browser, nworld)
            out["pages_still"] = chromium_viewers(url, nworld, pages, seconds, False, browser)
            out["pages_moving"] = chromium_viewers(url, nworld, pages, seconds, True, browser)
        finally:
            browser.close()
    return out


def rows(r: dict[str, Any]) -> list[dict[str, Any]]:
    """The printed table: one row per viewer set-up."""
    n, k = r["nworld"], r["pages"]
    out = [
        {"viewers": "none, arms still", "RTF": r["alone"]["rtf"]},
        {"viewers": f"none, {MOVING} arms moving", "RTF": r["alone_moving"]["rtf"]},
    ]
    out.append(
        {
            "viewers": f"{k} sockets (pose frames of {n}, no drawing), {MOVING} arms moving",
            "RTF": r["sockets"]["rtf"],
            "frames/s each": r["sockets"]["frames_per_s"]["mean"],
            "min": r["sockets"]["frames_per_s"]["min"],
        }
    )
    for key, label in (("pages_still", "arms still"), ("pages_moving", f"{MOVING} arms moving")):
        m = r[key]
        out.append(
            {
                "viewers": f"{k} Chromium pages, fleet of {n}, {label}",
                "RTF": m["rtf"],
                "frames/s each": m["frames_per_s"]["mean"],
                "min": m["frames_per_s"]["min"],
                "drawn/s each": m["draws_per_s"]["mean"],
                "load ms": m["load_ms"]["mean"],
            }
        )
    singles = (("page_1_world", "world view of 1"), (f"page_{n}_worlds", f"fleet of {n}"))
    for key, label in singles:
        m = r[key]
        out.append(
            {
                "viewers": f"1 Chromium page, {label}, {MOVING} arms moving",
                "RTF": m["rtf"],
                "frames/s each": m["frames_per_s"],
                "drawn/s each": m["draws_per_s"],
                "load ms": m["load_ms"],
            }
        )
    return out


@section(9, "viewers")
def viewers(ctx: Context) -> Result:
    """Many viewers: headless Chromium pages on a realtime service

    Twenty pages (four with --quick) watching every world of a 64-world realtime service."""
    from clients.testing import headless

    reason = headless.why_unavailable()
    if reason:
        return Result([], data={"errors": {"chromium": reason}})
    pages = ctx.pick(PAGES, 4)
    seconds = ctx.pick(10.0, 4.0)
    results, errors = ctx.each(
        ctx.sizes((64,)),
        lambda n: _measured(ctx, n, pages, seconds),
        lambda r: (
            f"RTF alone {r['alone']['rtf']}, {r['pages']} pages moving {r['pages_moving']['rtf']}"
        ),
    )
    table = [{"worlds": int(n), **row} for n, r in results.items() for row in rows(r)]
    notes = [
        "Chromium draws WebGL in software (SwiftShader) on the same CPU cores as the service: "
        "on a small machine the rows with drawing measure that competition, the socket row "
        "the server's own cost of the viewers.",
        "frames/s: pose frames each viewer received (asked: 30/s; never more than the loop's "
        "ticks/s); drawn/s: frames the page drew (only when something moved; software GL "
        "draws at most at the stream rate); load ms: navigation start to the first frame drawn.",
    ]
    data = {"pages": pages, "seconds": seconds, "results": results, "errors": errors}
    return Result(table, data, notes)


def _measured(ctx: Context, nworld: int, pages: int, seconds: float) -> dict[str, Any]:
    with ctx.serve(nworld, "realtime") as server:
        return measure(server.url, nworld, pages, seconds)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
