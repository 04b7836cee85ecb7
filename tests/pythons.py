"""Other Python interpreters on this machine, for the tests of what runs outside armfleet's own
3.11+ venv: `scripts/dev.py` started by an older python3, the client library installed alone.

They are found by `scripts/_pyfind.py` itself (PATH, /usr/bin, /usr/local/bin, pyenv's versions),
the same search dev.py does, so the tests use what a developer's machine really has.
"""

from __future__ import annotations

import functools
import importlib.util
import os
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def load_pyfind() -> ModuleType:
    """scripts/_pyfind.py as a module (scripts/ is not a package)."""
    spec = importlib.util.spec_from_file_location("_pyfind", ROOT / "scripts" / "_pyfind.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


pyfind = load_pyfind()


@functools.cache
def interpreter(version: tuple[int, int]) -> str | None:
    """A working python of that (major, minor) version here, or None. Only names that can be it
    (python3.N, python3) are run, and each at most once: pyenv's shims take a while to answer."""
    name = f"python{version[0]}.{version[1]}"
    for exe in _candidates():
        if os.path.basename(exe) in (name, "python3") and _version(exe) == version:
            return exe
    return None


def older_than_311() -> list[str]:
    """The oldest (3.8, dev.py's floor) and newest (3.10) interpreters before 3.11 found here."""
    found = (interpreter((3, minor)) for minor in (8, 10))
    return [exe for exe in found if exe]


@functools.cache
def _candidates() -> tuple[str, ...]:
    dirs = ("/usr/local/bin", "/usr/bin")
    return tuple(pyfind.candidates(os.environ.get("PATH", ""), Path.home(), dirs))


@functools.cache
def _version(exe: str) -> tuple[int, int] | None:
    return pyfind.version_of(exe)
