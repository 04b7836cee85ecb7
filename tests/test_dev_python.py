"""`python3 scripts/dev.py ...` started by a Python older than 3.11 (Ubuntu 22.04's is 3.10):
it restarts itself with a newer interpreter found on the machine, or stops at once naming what to
install (scripts/_pyfind.py).

The search is driven over fake PATHs whose `python3.N` are small shell scripts answering the
version probe as a real one would (stand-ins for the operating system, not for armfleet). The
restart itself runs the real dev.py under the real older interpreters this machine has (pyenv's).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from pythons import ROOT, older_than_311, pyfind

UBUNTU_2204 = 'NAME="Ubuntu"\nID=ubuntu\nVERSION_ID="22.04"\n'


def fake_python(
    where: Path, name: str, version: str | None, sleep: float = 0, venv: bool = True
) -> Path:
    """An executable answering the probe as python `version` ("3.12") would, with or without
    the venv module; version None: it fails."""
    where.mkdir(parents=True, exist_ok=True)
    exe = where / name
    answer = "exit 1" if version is None else f"echo {version.replace('.', ' ')} {int(venv)}"
    exe.write_text(f"#!/bin/sh\nsleep {sleep}\n{answer}\n")
    exe.chmod(0o755)
    return exe


def choose(path: list[Path], home: Path, current: tuple[int, int] = (3, 10), **env: str) -> str:
    return pyfind.choose(current, {"PATH": os.pathsep.join(map(str, path)), **env}, home, dirs=())


def test_a_tested_version_is_preferred_and_broken_ones_are_skipped(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    fake_python(a, "python3", "3.10")
    fake_python(a, "python3.13", "3.13")
    fake_python(a, "python3.12", None)  # e.g. a pyenv shim for a version not selected
    python311 = fake_python(b, "python3.11", "3.11")
    assert choose([a, b], tmp_path) == str(python311)
    python311.unlink()
    assert choose([a, b], tmp_path) == str(a / "python3.13")
    assert choose([a, b], tmp_path, current=(3, 12)) is None  # new enough: no restart


def test_pyenv_versions_and_uv_are_searched(tmp_path: Path) -> None:
    home = tmp_path / "home"
    pyenv = fake_python(home / ".pyenv" / "versions" / "3.12.1" / "bin", "python3.12", "3.12")
    assert choose([tmp_path / "empty"], home) == str(pyenv)
    managed = fake_python(tmp_path / "uv-pythons", "python3.14", "3.14")
    uv = tmp_path / "bin" / "uv"
    uv.parent.mkdir()
    uv.write_text(f"#!/bin/sh\n[ \"$1 $2 $3\" = 'python find >=3.11' ] && echo {managed}\n")
    uv.chmod(0o755)
    assert choose([uv.parent], tmp_path) == str(managed)


def test_one_without_venv_is_passed_over_or_named_with_its_package(tmp_path: Path) -> None:
    """Ubuntu 22.04 after `apt install python3.11` alone: python3.11 has no ensurepip."""
    release = tmp_path / "os-release"
    release.write_text(UBUNTU_2204)
    bare = fake_python(tmp_path / "bin", "python3.11", "3.11", venv=False)
    env = {"PATH": str(tmp_path / "bin")}
    with pytest.raises(SystemExit) as stop:
        pyfind.choose((3, 10), env, tmp_path, dirs=(), release_file=str(release))
    assert f"{bare} is Python 3.11 but cannot make a virtualenv" in str(stop.value.code)
    assert "Install: sudo apt install python3.11-venv" in str(stop.value.code)
    pyenv = fake_python(tmp_path / ".pyenv" / "versions" / "3.12.1" / "bin", "python3.12", "3.12")
    assert pyfind.choose((3, 10), env, tmp_path, dirs=()) == str(pyenv)


def test_a_hanging_interpreter_is_given_up_on(tmp_path: Path) -> None:
    exe = fake_python(tmp_path, "python3.12", "3.12", sleep=2)
    assert pyfind.version_of(str(exe), timeout=0.5) is None


def test_none_new_enough_names_the_packages_to_install(tmp_path: Path) -> None:
    fake_python(tmp_path / "bin", "python3", "3.10")
    release = tmp_path / "os-release"
    release.write_text(UBUNTU_2204)
    env = {"PATH": str(tmp_path / "bin")}
    with pytest.raises(SystemExit) as stop:
        pyfind.choose((3, 10), env, tmp_path, dirs=(), release_file=str(release))
    message = str(stop.value.code)
    assert "this python is 3.10" in message
    assert "Install one: sudo apt install python3.11 python3.11-venv" in message
    for distro, hint in [
        ({"ID": "debian", "VERSION_ID": "12"}, "sudo apt install python3 python3-venv"),
        ({"ID": "fedora", "VERSION_ID": "40"}, "sudo dnf install python3.11"),
        ({"ID": "debian", "VERSION_ID": "11"}, "`pyenv install 3.11` or `uv python install"),
    ]:
        assert hint in pyfind.install_hint(distro), distro
    assert pyfind.venv_hint((3, 11), {"ID": "ubuntu"}) == "sudo apt install python3.11-venv"


def test_armfleet_python_is_used_as_given_or_refused_by_name(tmp_path: Path) -> None:
    new, old = fake_python(tmp_path, "py312", "3.12"), fake_python(tmp_path, "py310", "3.10")
    assert choose([], tmp_path, current=(3, 12), ARMFLEET_PYTHON=str(new)) == str(new)
    with pytest.raises(SystemExit, match=f"ARMFLEET_PYTHON={old} is 3.10; armfleet needs"):
        choose([], tmp_path, ARMFLEET_PYTHON=str(old))


@pytest.fixture(scope="module")
def old_pythons() -> list[str]:
    found = older_than_311()
    if not found:
        pytest.skip("no Python older than 3.11 here (`pyenv install 3.10` gives one)")
    return found


def test_a_venv_of_an_old_or_removed_python_is_made_anew(
    tmp_path: Path, old_pythons: list[str]
) -> None:
    """The .venv a 3.10 run left behind (its pip install failed) is replaced, not reused."""
    subprocess.run([old_pythons[-1], "-m", "venv", "--without-pip", tmp_path / "old"], check=True)
    assert pyfind.stale_venv(tmp_path / "old" / "bin" / "python").startswith("it was made by")
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", tmp_path / "new"], check=True)
    assert pyfind.stale_venv(tmp_path / "new" / "bin" / "python") is None
    gone = tmp_path / "gone"
    gone.symlink_to(tmp_path / "removed-python3.12")
    assert "is gone" in pyfind.stale_venv(gone)
    assert pyfind.stale_venv(tmp_path / "none") is None  # no venv yet: nothing to remove


def test_dev_py_under_an_old_python_restarts_with_a_new_one(
    tmp_path: Path, old_pythons: list[str]
) -> None:
    """The real dev.py, started by real 3.8 / 3.10 interpreters, restarts itself with the only
    3.11+ on its PATH, which then prints the usage (no command given: nothing is set up)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "python3.11").symlink_to(os.path.realpath(sys.executable))
    env = {"PATH": str(bin_dir), "HOME": str(tmp_path)}
    for old in old_pythons:
        run = subprocess.run(
            [old, str(ROOT / "scripts" / "dev.py")], env=env, capture_output=True, text=True
        )
        assert run.returncode == 2, run.stdout + run.stderr
        assert f"too old for armfleet (3.11+): restarting with {bin_dir}/python3.11" in run.stdout
        assert "python3 scripts/dev.py serve" in run.stdout  # the usage, from the new Python


def test_an_old_python_with_nothing_newer_stops_without_a_traceback(
    tmp_path: Path, old_pythons: list[str]
) -> None:
    release = tmp_path / "os-release"
    release.write_text(UBUNTU_2204)
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import _pyfind; from pathlib import Path; "
        "_pyfind.choose(sys.version_info[:2], {'PATH': ''}, Path(sys.argv[2]), (), sys.argv[3])"
    )
    for old in old_pythons:
        args = [old, "-c", code, str(ROOT / "scripts"), str(tmp_path), str(release)]
        run = subprocess.run(args, capture_output=True, text=True, env={"PATH": ""})
        assert run.returncode == 1 and "Traceback" not in run.stderr, run.stderr
        assert "sudo apt install python3.11 python3.11-venv" in run.stderr
