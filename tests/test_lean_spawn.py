"""A spawned worker started under `main_not_reimported` does not import the parent's main module
(service/core/process/lean_spawn.py: a shard worker no longer runs service/cli.py first)."""

from __future__ import annotations

import importlib.util
import multiprocessing as mp
import sys
from pathlib import Path

import pytest

from service.core.process.lean_spawn import main_not_reimported

MAIN = """import os, pathlib
pathlib.Path(os.environ["ARMFLEET_TEST_MAIN_MARK"]).write_text(__name__)
"""


def _child_main_name() -> None:
    """The spawned child's target (pickled by reference to this module, not to __main__)."""


def _start_child(lean: bool) -> None:
    proc = mp.get_context("spawn").Process(target=_child_main_name)
    if lean:
        with main_not_reimported():
            proc.start()
    else:
        proc.start()
    proc.join(120)
    assert proc.exitcode == 0


def test_a_spawned_worker_does_not_import_the_main_module_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "armfleet_fake_main.py").write_text(MAIN)
    monkeypatch.syspath_prepend(str(tmp_path))  # the child gets the parent's sys.path
    spec = importlib.util.find_spec("armfleet_fake_main")
    fake_main = importlib.util.module_from_spec(spec)  # as `python -m armfleet_fake_main` has it
    monkeypatch.setitem(sys.modules, "__main__", fake_main)
    mark = tmp_path / "imported"
    monkeypatch.setenv("ARMFLEET_TEST_MAIN_MARK", str(mark))

    _start_child(lean=False)  # plain spawn: the child runs the main module as __mp_main__
    assert mark.read_text() == "__mp_main__"
    mark.unlink()

    _start_child(lean=True)
    assert not mark.exists()
    assert sys.modules["__main__"] is fake_main  # the parent's main module is back
