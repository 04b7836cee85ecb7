"""The page with a lease (Chromium via Playwright): /?lease=<token> shows and drives the
lease's worlds only, takes the token out of the address bar, and says when a lease is over."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest
from conftest import HOME, Server, serve, wait_for

from tests.test_page import open_page, page, reconnected  # noqa: F401 (fixtures; `browser` is conftest's)

try:
    from playwright.sync_api import expect
except ImportError:  # the `browser` fixture skips and says why
    expect = None


@pytest.fixture(scope="module")
def srv(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    extra = ("--leases", "optional", "--engine", "mujoco")
    with serve(worlds=4, extra_args=extra, log_dir=tmp_path_factory.mktemp("page")) as server:
        yield server


def lend(srv: Server, worlds: list[int]) -> dict:
    r = httpx.post(f"{srv.url}/v1/leases", json={"worlds": worlds, "ttl_s": 120, "label": "bo"})
    assert r.status_code == 201, r.text
    return r.json()


def target(srv: Server, world: int) -> list[float]:
    return httpx.get(f"{srv.url}/v1/worlds/{world}/state").json()["target"]


def test_the_page_drives_and_shows_its_lease_worlds_only(srv, page) -> None:  # noqa: F811
    lease = lend(srv, [1, 2])
    open_page(page, srv, f"?view=fleet&lease={lease['token']}")
    assert "lease=" not in page.url and lease["token"] not in page.url
    labels = page.locator(".wlabel")
    expect(labels).to_have_count(2)
    assert [labels.nth(i).inner_text() for i in range(2)] == ["1", "2"]
    expect(page.locator("#world")).to_have_value("1")
    page.locator('tr[data-joint="elbow_joint"]').get_by_role("button", name="Up (+0.1)").click()
    wait_for(lambda: target(srv, 1)[2] == pytest.approx(HOME[2] + 0.1), "world 1's elbow")
    page.locator("#world").fill("3")
    page.locator("#world").dispatch_event("change")
    expect(page.locator("#message")).to_contain_text("world 3 is not in your lease")
    expect(page.locator("#world")).to_have_value("1")
    assert target(srv, 3) == pytest.approx(HOME)
    page.locator('.wlabel[data-world="2"]').click()
    expect(page.locator("#world")).to_have_value("2")
    reconnected(page)
    page.locator('tr[data-joint="elbow_joint"]').get_by_role("button", name="Up (+0.1)").click()
    wait_for(lambda: target(srv, 2)[2] == pytest.approx(HOME[2] + 0.1), "world 2's elbow")
    httpx.delete(
        f"{srv.url}/v1/leases/{lease['id']}", headers={"Authorization": f"Bearer {lease['token']}"}
    )


def test_the_page_asks_for_a_token_and_says_when_a_lease_is_over(srv, page) -> None:  # noqa: F811
    lease = lend(srv, [3])
    page.once("dialog", lambda dialog: dialog.accept(lease["token"]))
    open_page(page, srv, "?lease")
    expect(page.locator("#world")).to_have_value("3")
    httpx.delete(
        f"{srv.url}/v1/leases/{lease['id']}", headers={"Authorization": f"Bearer {lease['token']}"}
    )
    page.reload()  # the tab kept the lease; it has ended since
    expect(page.locator("#banner")).to_contain_text("lease not usable", timeout=15_000)


def test_the_student_link_is_logged_with_its_token_blanked(srv, page) -> None:  # noqa: F811
    """Issue 38, item 2: the documented link /?lease=<token>, opened in Chromium, gives uvicorn's
    access line with the token blanked, and no `--- Logging error ---` traceback (the filter
    once dropped the record's arguments, which uvicorn's access formatter unpacks)."""
    lease = lend(srv, [3])
    start = srv.log_path.stat().st_size
    open_page(page, srv, f"?lease={lease['token']}")
    expect(page.locator("#world")).to_have_value("3")

    def access_line() -> str | None:
        new = srv.log_path.read_bytes()[start:].decode(errors="replace")
        return next((ln for ln in new.splitlines() if '"GET /?lease=' in ln), None)

    line = wait_for(access_line, "the page's access line")
    assert "lease=<redacted>" in line and " 200" in line, line
    logged = srv.log_path.read_bytes()[start:].decode(errors="replace")
    assert lease["token"] not in logged
    assert "Logging error" not in logged and "Traceback" not in logged, logged[-2000:]
