"""Find a Python new enough for armfleet when `scripts/dev.py` is started by an older one.

armfleet needs Python 3.11+ (MuJoCo 4), but the first command people type is `python3 ...`,
and on Ubuntu 22.04 (ROS 2 Humble's platform) `python3` is 3.10. Rather than end in pip's
resolver error about `mujoco==4.0.0`, dev.py asks this module for a newer interpreter already on
the machine and restarts itself with it, or stops at once naming the packages to install.

Standard library only, Python 3.8 syntax: this runs before anything is installed.
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import subprocess
from pathlib import Path

NEED = (3, 11)
# Tried first, in this order: the versions armfleet's CI and GPU machines run; then any newer.
PREFERRED = ((3, 11), (3, 12), (3, 13))
EXPLICIT = "ARMFLEET_PYTHON"  # a user's own choice of interpreter, used as given
_NAME = re.compile(r"^python3(\.\d+)?$")
# Version, and whether `venv` can put pip in (Debian and Ubuntu ship ensurepip apart, in
# python3.N-venv: without it `python3.N -m venv` fails).
_PROBE = (
    "import sys, importlib.util as u;"
    "print(sys.version_info[0], sys.version_info[1], int(u.find_spec('ensurepip') is not None))"
)


def dotted(version: tuple[int, int]) -> str:
    return ".".join(str(part) for part in version)


def probe(exe: str, timeout: float = 10.0) -> tuple[tuple[int, int], bool] | None:
    """((major, minor), has venv's ensurepip) of an interpreter, or None when it does not run
    (a pyenv shim for a version not selected, a dangling link, a hang)."""
    try:
        out = subprocess.run(
            [exe, "-c", _PROBE], capture_output=True, text=True, timeout=timeout, check=True
        ).stdout.split()
        return (int(out[0]), int(out[1])), out[2] == "1"
    except (OSError, subprocess.SubprocessError, ValueError, IndexError):
        return None


def version_of(exe: str, timeout: float = 10.0) -> tuple[int, int] | None:
    """The (major, minor) an interpreter reports, or None when it does not run."""
    found = probe(exe, timeout)
    return found[0] if found else None


def candidates(path: str, home: Path, dirs: tuple[str, ...]) -> list[str]:
    """Interpreters named python3 or python3.N: on PATH first, then in `dirs` and pyenv's
    versions, then the one `uv python find` reports. Duplicates (same file) are dropped."""
    places = [d for d in path.split(os.pathsep) if d]
    places += list(dirs) + sorted(glob.glob(str(home / ".pyenv" / "versions" / "*" / "bin")))
    found: list[str] = []
    for place in places:
        try:
            names = sorted(os.listdir(place), reverse=True)
        except OSError:
            continue
        found += [os.path.join(place, n) for n in names if _NAME.match(n)]
    uv = shutil.which("uv", path=path)
    if uv:
        try:
            out = subprocess.run(
                [uv, "python", "find", f">={dotted(NEED)}"],
                capture_output=True,
                text=True,
                timeout=20,
            )
            if out.returncode == 0 and out.stdout.strip():
                found.append(out.stdout.strip().splitlines()[-1])
        except (OSError, subprocess.SubprocessError):
            pass
    unique: list[str] = []
    seen: set[str] = set()
    for exe in found:
        key = os.path.realpath(exe)
        if key not in seen and os.access(exe, os.X_OK) and os.path.isfile(exe):
            seen.add(key)
            unique.append(exe)
    return unique


def best(interpreters: list[str]) -> tuple[str, tuple[int, int], bool] | None:
    """The interpreter to use, with its version and whether it can make a venv: one that can
    before one that cannot, then a PREFERRED version, else the newest that is new enough."""
    probed = ((exe, probe(exe)) for exe in interpreters)
    usable = [(exe, p[0], p[1]) for exe, p in probed if p and p[0] >= NEED]
    rank = {version: i for i, version in enumerate(PREFERRED)}

    def order(item: tuple[str, tuple[int, int], bool]) -> tuple[bool, int, tuple[int, int]]:
        _, version, venv = item
        return (not venv, rank.get(version, len(rank)), (-version[0], -version[1]))

    return min(usable, key=order) if usable else None


def stale_venv(python: Path) -> str | None:
    """Why the venv whose interpreter is `python` must be made anew, or None to keep it: made by
    a Python older than 3.11 (a run of dev.py before it knew better), or its interpreter gone.
    One that only failed to answer is kept: on a loaded machine the answer may have been slow."""
    if python.is_symlink() and not python.exists():
        return f"its Python ({os.readlink(python)}) is gone"
    made_by = version_of(str(python), timeout=60) if python.exists() else None
    if made_by is not None and made_by < NEED:
        return f"it was made by Python {dotted(made_by)}"
    return None


def os_release(path: str = "/etc/os-release") -> dict[str, str]:
    """ID and VERSION_ID etc. of this Linux distribution ({} where the file is missing)."""
    try:
        lines = Path(path).read_text().splitlines()
    except OSError:
        return {}
    pairs = (line.split("=", 1) for line in lines if "=" in line)
    return {k.strip(): v.strip().strip('"') for k, v in pairs}


def install_hint(release: dict[str, str]) -> str:
    """What to install on this distribution to get a Python 3.11+ with its venv module."""
    distro, version = release.get("ID", ""), release.get("VERSION_ID", "")
    if distro == "ubuntu" and version == "22.04":
        return "sudo apt install python3.11 python3.11-venv"
    if distro in ("ubuntu", "debian") and _newer_default(distro, version):
        return "sudo apt install python3 python3-venv"
    if distro == "fedora":
        return "sudo dnf install python3.11"
    return (
        "Python 3.11 or newer with its venv module, from your distribution, python.org, "
        "`pyenv install 3.11` or `uv python install 3.11`"
    )


def venv_hint(version: tuple[int, int], release: dict[str, str]) -> str:
    """What gives an interpreter that lacks it the venv module (Debian and Ubuntu split it off)."""
    if release.get("ID") in ("ubuntu", "debian"):
        return f"sudo apt install python{dotted(version)}-venv"
    return f"the venv module of Python {dotted(version)} (a package of your distribution)"


def _newer_default(distro: str, version: str) -> bool:
    """Whether the distribution's own python3 is already 3.11+ (Debian 12+, Ubuntu 23.04+)."""
    try:
        number = float(version)
    except ValueError:
        return False
    return number >= (12 if distro == "debian" else 23.04)


def choose(
    current: tuple[int, int],
    env: dict[str, str],
    home: Path,
    dirs: tuple[str, ...] = ("/usr/local/bin", "/usr/bin"),
    release_file: str = "/etc/os-release",
) -> str | None:
    """None when the running Python will do; else the interpreter to restart with.
    Raises SystemExit with what to install when there is none (no traceback, exit status 1)."""
    explicit = env.get(EXPLICIT)
    if explicit:
        version = version_of(explicit)
        if version is None or version < NEED:
            got = "does not run" if version is None else f"is {dotted(version)}"
            raise SystemExit(f"{EXPLICIT}={explicit} {got}; armfleet needs Python 3.11 or newer")
        return explicit
    if current >= NEED:
        return None
    found = best(candidates(env.get("PATH", ""), home, dirs))
    if found and found[2]:
        return found[0]
    if found:
        raise SystemExit(
            f"{found[0]} is Python {dotted(found[1])} but cannot make a virtualenv (no venv "
            f"module).\nInstall: {venv_hint(found[1], os_release(release_file))}\n"
            "then run the same command again."
        )
    uv = ["`uv python find`"] if shutil.which("uv", path=env.get("PATH", "")) else []
    looked = ", ".join(["PATH", *dirs, "~/.pyenv/versions", *uv])
    raise SystemExit(
        f"armfleet needs Python 3.11 or newer (MuJoCo 4), and this python is {dotted(current)};"
        f" none newer was found (looked in {looked}).\n"
        f"Install one: {install_hint(os_release(release_file))}\n"
        f"then run the same command again: it will use it ({EXPLICIT}=/path/to/python picks one)."
    )
