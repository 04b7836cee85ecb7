"""Headless Chromium for the page's tests and the bench: Debian's `chromium`, driven by Playwright.

Playwright's own browser download is not used (our machines cannot reach it): the apt package
is launched by path. It renders WebGL2 in software (SwiftShader), which is what the tests and the
bench measure; the sandbox is off because CI runs as root.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

ARGS = (
    "--no-sandbox",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
)


def chromium_path() -> str | None:
    """Where Debian's chromium is, or None when it is not installed."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found:
        return found
    return "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None


def why_unavailable() -> str | None:
    """None when headless pages can run here, else the reason (for pytest.skip)."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "Playwright is not installed (pip install playwright)"
    if chromium_path() is None:
        return "Debian's chromium is not installed (scripts/dev.py test installs it with apt)"
    return None


def launch(playwright: Any, **kwargs: Any) -> Any:
    """Launch chromium through a (sync or async) Playwright instance."""
    return playwright.chromium.launch(executable_path=chromium_path(), args=list(ARGS), **kwargs)
