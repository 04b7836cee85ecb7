"""MkDocs hooks of the documentation site: pages that are generated from the code at build time.

Why hooks and not mkdocs-gen-files or a macros plugin: one small module with no extra
dependency does it. The reference pages are ordinary files under docs/ (so the nav, links and
search treat them like any page) holding a placeholder that is replaced while the site builds:

    {{ gen openapi }}    the HTTP API from the app's OpenAPI schema (openapi_md)
    {{ gen cli }}        the `armfleet` command from its Typer app (cli_md)
    {{ gen settings }}   settings and ARMFLEET_* variables from the Settings model (settings_md)
    {{ gen layers }}     the layers and what each may import (layers_md)
    {{ gen modules }}    every module with its docstring's summary (layers_md)
    {{ gen headline }}   how many worlds in real time, CPU and GPU (bench/figures.py)
    {{ table NAME }}     a bench table: one of bench/readme_tables.TABLES, or a results file
    {{ fig NAME }}       one measured figure for prose (bench/figures.FIGURES)

An unknown placeholder, or one whose source fails, stops the build: nothing stale is shown.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mkdocs.exceptions import PluginError

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def _on_path() -> None:
    """This checkout's service/bench/clients and the generators here come first on the path
    (MkDocs restores sys.path after loading a hook module, so this runs at build time)."""
    for folder in (ROOT, HERE):
        if str(folder) in sys.path:
            sys.path.remove(str(folder))
        sys.path.insert(0, str(folder))


PLACEHOLDER = re.compile(r"\{\{ (gen|table|fig) ([\w./-]+) \}\}")

# The result file whose machine, date and command a readme_tables table comes from.
TABLE_SOURCES = {
    "gpu": "throughput_cuda.json",
    "profile": "tick_profile_cuda.json",
    "baseline": "warp_baseline_cuda.json",
    "capacity": "capacity_engines.json",
}


def _generators() -> dict[str, Callable[[], str]]:
    import cli_md
    import layers_md
    import openapi_md
    import settings_md

    from bench import figures

    return {
        "openapi": openapi_md.render,
        "cli": cli_md.render,
        "settings": settings_md.render,
        "layers": layers_md.render,
        "modules": layers_md.modules,
        "headline": figures.headline,
    }


def _table(name: str) -> str:
    from bench import figures, readme_tables

    if name in readme_tables.TABLES:
        text = readme_tables.TABLES[name]()
        source = TABLE_SOURCES.get(name)
        if source:
            text += "\n\n" + figures.caption(figures.load(source))
        elif name == "capacity_runs":  # one file a run: the machine and command of the latest
            latest = max(readme_tables.CAPACITY_RUNS.glob("*.json"))
            folder = latest.relative_to(readme_tables.common.RESULTS_DIR)
            text += "\n\nLatest: " + figures.caption(figures.load(str(folder)))
        return text
    return figures.section_table(name)


_cache: dict[tuple[str, str], str] = {}


def on_pre_build(config: Any) -> None:
    _on_path()
    _cache.clear()  # `mkdocs serve` rebuilds: read the code and results again


def _render(kind: str, name: str) -> str:
    from bench import figures

    if (kind, name) not in _cache:
        if kind == "gen":
            generators = _generators()
            if name not in generators:
                raise KeyError(f"unknown generator {name!r}; known: {', '.join(generators)}")
            _cache[kind, name] = generators[name]()
        elif kind == "table":
            _cache[kind, name] = _table(name)
        else:
            _cache[kind, name] = figures.figure(name)
    return _cache[kind, name]


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    def replace(match: re.Match[str]) -> str:
        try:
            return _render(match.group(1), match.group(2))
        except Exception as exc:  # any failure of a generator fails the build, naming the page
            raise PluginError(
                f"{page.file.src_path}: {match.group(0)} failed: {type(exc).__name__}: {exc}"
            ) from exc

    return PLACEHOLDER.sub(replace, markdown)
