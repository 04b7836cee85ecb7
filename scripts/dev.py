#!/usr/bin/env python3
"""One-command set-up for a fresh machine with nothing but python3.

    python3 scripts/dev.py serve [armfleet serve options]   set up, warm the kernel cache, serve
    python3 scripts/dev.py test  [pytest options]           set up, warm the cache, lint + tests
                                                            (a pytest worker a core, and one more)

Set-up is idempotent and quick when nothing changed: a virtualenv in .venv, the project
installed editable with its pinned dependencies (re-installed only when pyproject.toml
changes), and MuJoCo Warp's kernels compiled into ~/.cache/warp with visible progress.

armfleet needs Python 3.11+; started by an older python3 (Ubuntu 22.04's is 3.10) this script
restarts itself with a newer one found on the machine, or stops naming what to install
(scripts/_pyfind.py). It must therefore still parse and start on Python 3.8.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import _pyfind  # beside this file

ROOT = Path(__file__).resolve().parents[1]
VENV = ROOT / ".venv"
BIN = VENV / "bin"
STAMP = VENV / ".armfleet-installed"
RESTARTED = "ARMFLEET_DEV_RESTARTED"  # set when this script restarted itself with another Python
# What the UI tests drive: a virtual X display, a pointer, a terminal multiplexer, and the
# browser the page's tests load it in (Playwright drives it; its own download is not used).
TEST_DEBS = {
    "Xvfb": "xvfb",
    "xdotool": "xdotool",
    "tmux": "tmux",
    "xwd": "x11-apps",
    "chromium": "chromium",
    # the ROS 2 judge's build (tests/ros2_judge.py: rosidl generators over CMake)
    "cmake": "cmake",
    "g++": "g++",
    # urdfdom, the C++ URDF parser RViz and robot_state_publisher use (tests/test_ros_ur.py)
    "check_urdf": "liburdfdom-tools",
}


def say(msg: str) -> None:
    print(f"\033[1m[armfleet]\033[0m {msg}", flush=True)


def run(*cmd: str | Path, **kw) -> None:
    subprocess.run([str(c) for c in cmd], check=True, cwd=ROOT, **kw)


def use_new_enough_python(argv: list[str]) -> None:
    """Restart with a Python 3.11+ when this one is older, or with the one ARMFLEET_PYTHON
    names."""
    if os.environ.get(RESTARTED):
        return
    exe = _pyfind.choose(sys.version_info[:2], dict(os.environ), Path.home())
    if exe is None:
        return
    old = sys.version_info < _pyfind.NEED
    why = "is too old for armfleet (3.11+)" if old else f"is not {_pyfind.EXPLICIT}"
    say(f"python {sys.version.split()[0]} {why}: restarting with {exe}")
    env = {**os.environ, RESTARTED: exe}
    os.execve(exe, [exe, str(Path(__file__).resolve()), *argv], env)


def ensure_venv() -> None:
    python = BIN / "python"
    stale = _pyfind.stale_venv(python)
    if stale:
        say(f"removing {VENV}: {stale}")
        shutil.rmtree(VENV)
    if not python.exists():
        say(f"creating virtualenv in {VENV} with {sys.executable}")
        if subprocess.run([sys.executable, "-m", "venv", str(VENV)], cwd=ROOT).returncode:
            shutil.rmtree(VENV, ignore_errors=True)
            hint = _pyfind.venv_hint(sys.version_info[:2], _pyfind.os_release())
            sys.exit(f"{sys.executable} cannot create a virtualenv. Install: {hint}")
    want = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    if STAMP.exists() and STAMP.read_text() == want:
        return
    say("installing armfleet and its pinned dependencies (mujoco, mujoco-warp, warp-lang, ...)")
    run(BIN / "python", "-m", "pip", "install", "--quiet", "--upgrade", "pip")
    # setuptools' build backend warns about editable installs in general (nothing to act on).
    quiet_backend = {**os.environ, "PYTHONWARNINGS": "ignore::UserWarning"}
    run(BIN / "python", "-m", "pip", "install", "--quiet", "-e", ".[test,bench]", env=quiet_backend)
    STAMP.write_text(want)


def warm_kernel_cache() -> None:
    run(BIN / "armfleet", "setup")


def ensure_test_tools() -> None:
    missing = [
        deb for tool, deb in TEST_DEBS.items() if not (shutil.which(tool) or Path(tool).exists())
    ]
    if not missing:
        return
    sudo = [] if os.geteuid() == 0 else ["sudo", "-n"]
    if shutil.which("apt-get") is None or (sudo and shutil.which("sudo") is None):
        say(f"cannot install {missing} (no apt-get or no root): the UI tests will be skipped")
        return
    say(f"installing test tools: {' '.join(missing)}")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    run(*sudo, "apt-get", "update", "-qq", env=env)
    run(*sudo, "apt-get", "install", "-y", "-qq", "--no-install-recommends", *missing, env=env)


def compile_sources() -> None:
    """Byte-compile the project's modules (quick when nothing changed: a stat per file).

    Where PYTHONDONTWRITEBYTECODE is set (as in this project's shared work sessions), Python
    reads cached bytecode but never writes it, so every process compiled the project from
    source: about 0.3 s of CPU for each of the ~100 servers and other Python processes the
    suite starts. compileall writes it regardless; `__pycache__/` is ignored by git."""
    dirs = ["service", "clients", "mjcf", "bench", "scripts", "tests"]
    run(BIN / "python", "-m", "compileall", "-q", "-x", "node_modules", *dirs)


def build_ros2_judge() -> None:
    """The real ROS 2 (Jazzy rclpy + Fast DDS, ../shared/ros2_judge) the ROS 2 tests run on,
    built once per version of its sources under ~/.cache/armfleet (tests/ros2_judge.py)."""
    done = subprocess.run([BIN / "python", "-m", "tests.ros2_judge"], cwd=ROOT)
    if done.returncode:
        say("the ROS 2 judge could not be built: the ROS 2 node's tests will be skipped")


def ensure_js_tools() -> None:
    """roslib.js for the rosbridge tests, pinned by tests/js/package-lock.json."""
    js = ROOT / "tests" / "js"
    if (js / "node_modules" / "roslib").exists():
        return
    npm = shutil.which("npm")
    if npm is None:
        say("npm not found: the roslib.js tests will be skipped (install Node 20+ to run them)")
        return
    say("installing roslib.js for the rosbridge tests (npm ci in tests/js)")
    subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=js, check=True)


def main(argv: list[str]) -> int:
    use_new_enough_python(argv)
    if not argv or argv[0] not in ("serve", "test"):
        print(__doc__)
        return 2
    command, rest = argv[0], argv[1:]
    ensure_venv()
    if command == "test":
        ensure_test_tools()
        build_ros2_judge()
        ensure_js_tools()
    warm_kernel_cache()
    compile_sources()
    if command == "serve":
        os.execv(BIN / "armfleet", [str(BIN / "armfleet"), "serve", *rest])
    say("ruff check + format check")
    run(BIN / "ruff", "check", ".")
    run(BIN / "ruff", "format", "--check", ".")
    say("pytest")
    pytest = [BIN / "python", "-m", "pytest", *parallel(rest), *rest]
    return subprocess.run(pytest, cwd=ROOT).returncode


def parallel(rest: list[str]) -> list[str]:
    """pytest-xdist options: one worker a core and one more, each test file on one worker (a
    module's servers start once) and handed out in collection order (tests/conftest.py puts the
    longest first), unless the options given choose (-n, --dist, -p no:xdist).

    The extra worker: about a third of a file's wall time is waiting, not computing (ROS
    discovery, Ray starting its daemons, a server's subprocesses), and a worker a core leaves
    the cores idle then."""
    chosen = any(a.startswith(("-n", "--numprocesses", "--dist")) or "no:xdist" in a for a in rest)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if chosen or (cores or 1) < 2:
        return []
    return ["-n", str(cores + 1), "--dist", "loadfile", "--no-loadscope-reorder"]


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
