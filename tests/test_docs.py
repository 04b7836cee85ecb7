"""The documentation site and the README cannot lie: the site builds with `mkdocs build --strict`
(a broken link, a missing page, a placeholder or reference that no longer resolves fails it),
its generated references hold what the code holds, no page speaks of tracker items, and a
measured figure comes from bench/results, not from a hand.
"""

from __future__ import annotations

import html
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from bench import figures, readme_tables

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
PAGES = sorted(DOCS.rglob("*.md"))

# "issue 20", "issues 13 and 16", "#20 of the tracker"; and the word "session(s)" on its own
# (class names such as WorldSession are not words of their own and do not match).
TRACKER = re.compile(r"(?i)\bissues?\s*#?\d+(?![\w/])|\bsessions?\b")
# A measured ratio typed into prose: "0.94×". Prose takes figures from `{{ fig ... }}`.
RATIO = re.compile(r"\d×(?!\d)")  # a ratio, not a size (320×240)
FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
BENCH_BLOCK = re.compile(r"<!-- bench:(\w+) -->.*?<!-- /bench:\1 -->", re.S)


def build(config: Path, site: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    done = build(ROOT / "mkdocs.yml", out)
    assert done.returncode == 0, done.stdout + done.stderr
    return out


def text_of(page: Path) -> str:
    """The page's words as a reader sees them: tags dropped, entities decoded, one space."""
    return " ".join(html.unescape(re.sub(r"<[^>]+>", "", page.read_text())).split())


def words(markdown: str) -> str:
    """Markdown as it reads once rendered (code marks and emphasis dropped, one space)."""
    return " ".join(markdown.replace("`", "").strip("*").split())


def test_the_site_builds_strict_with_every_page_of_the_nav(site: Path) -> None:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())

    def pages(nav: list) -> list[str]:
        out = []
        for item in nav:
            value = next(iter(item.values())) if isinstance(item, dict) else item
            out += pages(value) if isinstance(value, list) else [value]
        return out

    listed = pages(config["nav"])
    assert sorted(listed) == sorted(str(p.relative_to(DOCS)) for p in PAGES)
    for page in listed:
        built = site / page.removesuffix(".md").removesuffix("index") / "index.html"
        assert built.exists(), page


def test_the_http_reference_lists_every_route_the_app_serves(site: Path) -> None:
    from service.app import create_app

    page = text_of(site / "reference/http/index.html")
    schema = create_app().openapi()
    for path, ops in schema["paths"].items():
        for method in ops:
            assert f"{method.upper()} {path}" in page, (method, path)
    for name in schema["components"]["schemas"]:
        assert name in page


def test_the_cli_and_settings_references_hold_every_command_and_variable(site: Path) -> None:
    import typer

    from service.cli import app
    from service.settings import flat_fields

    cli = text_of(site / "reference/cli/index.html")
    group = typer.main.get_command(app)
    for name in group.commands:  # type: ignore[attr-defined]
        assert f"armfleet {name}" in cli
    assert "--worlds" in cli and "ARMFLEET_WORLDS" in cli
    settings = text_of(site / "reference/settings/index.html")
    for name in flat_fields():
        assert f"ARMFLEET_{name.upper()}" in settings


def test_armfleet_help_lists_every_command() -> None:
    """Getting started: "`.venv/bin/armfleet --help` lists every command"."""
    import typer

    from service.cli import app

    names = list(typer.main.get_command(app).commands)  # type: ignore[attr-defined]
    assert {"serve", "controller", "watch", "replay", "setup", "bench", "docs"} <= set(names)
    env = {**os.environ, "COLUMNS": "200"}
    cmd = [sys.executable, "-m", "service.cli", "--help"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr
    listed = set(re.findall(r"^\W*([a-z]+)\s{2,}\S", out.stdout, re.M))
    assert set(names) <= listed, out.stdout


def test_the_client_reference_is_generated_from_the_docstrings(site: Path) -> None:
    from clients import ArmfleetClient

    page = (site / "reference/python-client/index.html").read_text()
    for method in ("increment", "set_targets", "stream", "follow_trajectory"):
        assert f'id="clients.client.ArmfleetClient.{method}"' in page
        summary = (getattr(ArmfleetClient, method).__doc__ or "").split("\n")[0].split("(")[0]
        assert words(summary)[:30] in text_of(site / "reference/python-client/index.html")


def test_the_figures_shown_are_those_of_bench_results(site: Path) -> None:
    home = text_of(site / "index.html")
    perf = text_of(site / "performance/index.html")
    for name in ("cpu.native_worlds", "gpu.realtime_worlds", "gpu.largest_fit"):
        assert figures.figure(name) in home and figures.figure(name) in perf
    assert words(figures.caption(figures.load("latency.json"))) in perf


# The small site of the broken-page test: a page with a generated figure and a link to a
# heading of the other page.
SMALL_SITE = {
    "index.md": (
        "# armfleet\n\nOn a CPU: {{ fig cpu.native_worlds }} worlds in real time. Start with\n"
        "[serving](getting-started.md#serve-and-test).\n"
    ),
    "getting-started.md": "# Getting started\n\n## Serve and test\n\n[Home](index.md)\n",
}


def small_site(at: Path, fault: str = "") -> Path:
    """The site's own mkdocs.yml (theme, hooks, plugins, markdown extensions and the strict
    link and anchor checks, unchanged) over the two pages of SMALL_SITE, with `fault` added at
    the end of the first: the config file written under `at`."""
    docs = at / "docs"
    docs.mkdir(parents=True)
    for name, text in SMALL_SITE.items():
        (docs / name).write_text(text + (f"\n\n{fault}\n" if name == "index.md" else ""))
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    config["docs_dir"] = str(docs)
    config["nav"] = [{"Home": "index.md"}, {"Getting started": "getting-started.md"}]
    config["hooks"] = [str(ROOT / h) for h in config["hooks"]]
    python = config["plugins"][1]["mkdocstrings"]["handlers"]["python"]
    python["paths"] = [str(ROOT)]
    (at / "mkdocs.yml").write_text(yaml.safe_dump(config, sort_keys=False))
    return at / "mkdocs.yml"


@pytest.fixture(scope="module")
def small_site_builds(tmp_path_factory: pytest.TempPathFactory) -> str:
    """The small site without a fault builds strict (so a fault is what fails it): the page
    it built."""
    at = tmp_path_factory.mktemp("small-site")
    done = build(small_site(at), at / "site")
    assert done.returncode == 0, done.stdout + done.stderr
    return text_of(at / "site" / "index.html")


@pytest.mark.parametrize(
    ("fault", "said"),
    [
        ("[a page that is not there](nowhere.md)", "nowhere.md"),
        ("[an anchor that is not there](getting-started.md#no-such-part)", "no-such-part"),
        ("{{ fig cpu.no_such_figure }}", "no_such_figure"),
        ("::: clients.client.NoSuchClient", "NoSuchClient"),
    ],
)
def test_a_broken_page_fails_the_build(
    small_site_builds: str, tmp_path: Path, fault: str, said: str
) -> None:
    """The strict build above could fail: a site with the same config, hooks and plugins
    fails it with one fault in a page. The site is small (it builds strict without the fault,
    its figure generated): the link and anchor checks run once every page is rendered, which
    takes ~9 s of CPU for the whole site, ~1.5 s for this one."""
    assert figures.figure("cpu.native_worlds") in small_site_builds  # the hooks ran there
    done = build(small_site(tmp_path, fault), tmp_path / "site")
    assert done.returncode != 0
    assert said in done.stdout + done.stderr


def test_no_page_speaks_of_tracker_items(site: Path) -> None:
    found = {
        str(p.relative_to(ROOT)): TRACKER.findall(p.read_text())
        for p in [README, *PAGES]
        if TRACKER.search(p.read_text())
    }
    built = {
        str(p.relative_to(site)): TRACKER.findall(text_of(p))
        for p in site.rglob("*.html")
        if TRACKER.search(text_of(p))
    }
    assert found == {} and built == {}


def test_the_checks_see_what_they_look_for() -> None:
    assert TRACKER.search("as issue 20 asked") and TRACKER.search("in this session")
    assert not TRACKER.search("AsyncWorldSession and the issues page")
    assert RATIO.search("binary 0.94× the engine")


def prose(text: str) -> str:
    """Text outside code blocks, placeholders and generated README blocks."""
    text = FENCE.sub("", BENCH_BLOCK.sub("", text))
    return re.sub(r"\{\{ .*? \}\}|`[^`]*`", "", text)


def test_no_measured_ratio_is_typed_by_hand() -> None:
    typed = {
        str(p.relative_to(ROOT)): RATIO.findall(prose(p.read_text()))
        for p in [README, *PAGES]
        if RATIO.search(prose(p.read_text()))
    }
    assert typed == {}


def test_the_readme_figures_are_current() -> None:
    """The README's generated blocks are what `python -m bench.readme_tables` writes today."""
    text = README.read_text()
    assert "<!-- bench:headline -->" in text
    assert readme_tables.update(text) == text, "run: python -m bench.readme_tables"


def test_the_readme_links_resolve() -> None:
    text = README.read_text()
    links = re.findall(r"\]\(([^)\s]+)\)", text)
    assert any(link.startswith("docs/") for link in links)
    for link in links:
        if re.match(r"[a-z]+:", link) or link.startswith("#"):
            continue
        path, _, anchor = link.partition("#")
        target = ROOT / path
        assert target.exists(), link
        if anchor and target.suffix == ".md":
            slugs = {
                re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
                for h in re.findall(r"^#+ (.+)$", target.read_text(), re.M)
            }
            assert anchor in slugs, link


def test_every_test_the_promises_table_names_exists() -> None:
    """docs/reference/promises.md names the test that holds each promise (`file::name`, or a
    whole file): a renamed or removed test would leave a promise that nothing checks."""
    table = (DOCS / "reference/promises.md").read_text()
    named = set(re.findall(r"\b(test_\w+\.py)(?:::(\w+))?", table))
    assert len(named) > 100
    missing = []
    for file, name in sorted(named):
        path = ROOT / "tests" / file
        if not path.is_file():
            missing.append(file)
        elif name and not re.search(rf"^(async )?def {name}\(", path.read_text(), re.M):
            missing.append(f"{file}::{name}")
    assert missing == []


def test_the_pytest_guide_example_is_the_one_the_suite_runs() -> None:
    """docs/guides/testing.md's example is tests/test_pytest_plugin.py's first test, word for
    word, so the page shows a test that passes."""
    guide = (DOCS / "guides/testing.md").read_text()
    (example,) = re.findall(r"```python\n(.*?)```", guide, re.S)
    body = example.split("\n\n\n", 1)[1]  # the test itself, after the imports
    assert body.strip() in (ROOT / "tests/test_pytest_plugin.py").read_text()


def test_armfleet_docs_serves_the_site_on_loopback() -> None:
    """`armfleet docs` builds the site and serves it on 127.0.0.1 until stopped."""
    import httpx

    from clients.testing import free_port, stop

    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    command = [sys.executable, "-m", "service.cli", "docs", "--port", str(port)]
    process = subprocess.Popen(
        command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    # One client polls: httpx.get() builds a TLS context at each call (~20 ms of CPU), and on
    # a loaded box the site takes 40 s to build.
    http = httpx.Client(timeout=5)
    try:
        deadline = time.monotonic() + 120
        while True:
            assert process.poll() is None, process.stdout.read().decode()  # type: ignore[union-attr]
            try:
                page = http.get(f"http://127.0.0.1:{port}/reference/http/")
                break
            except httpx.TransportError:
                assert time.monotonic() < deadline, "armfleet docs did not serve in 120 s"
                time.sleep(0.5)
        assert page.status_code == 200
        assert "POST /v1/worlds/{world}/increments" in html.unescape(page.text)
    finally:
        http.close()
        stop(process)
