"""Where the armfleet_ros node runs: the user's ROS 2 Python, and armfleet's client beside it.

`armfleet serve --ros2` starts the node (packaging/armfleet-ros) with the Python of the ROS 2
installation sourced in the shell (or `--ros2-python`): that Python has rclpy, the middleware and
the message packages; what it lacks is armfleet's client library and the node itself. Those are
installed once, by pip run for that Python (`pip --python`), into a folder of their own under
~/.cache/armfleet (keyed by the Python's version and the sources' hash), never into the ROS
installation; the Python's own numpy stays the one rclpy uses. Checkouts of other sources
install beside each other, never over or instead of each other (install_cache.py).
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from service.core.process.pythonpath import ORIGINAL
from service.surfaces.ros import install_cache

log = logging.getLogger("armfleet.ros")

REPO = Path(__file__).resolve().parents[3]
CLIENT_DIST = REPO / "packaging" / "armfleet-client"
NODE_DIST = REPO / "packaging" / "armfleet-ros"
CLIENTS = REPO / "clients"
CLIENT_DEPS = ("httpx>=0.27", "websockets>=13", "orjson>=3.10")  # numpy: the ROS Python's own
_PROBE = (
    "import rclpy, sensor_msgs.msg, control_msgs.action, tf2_msgs.msg, sys;"
    "print(sys.version_info[0], sys.version_info[1])"
)
_NO_ROS = (
    "--ros2 needs a ROS 2 installation: run `source /opt/ros/<distro>/setup.bash` first, "
    "or pass --ros2-python PATH (a Python that imports rclpy, control_msgs and tf2_msgs)"
)


@dataclass(frozen=True)
class NodeEnv:
    """How to start the node: the ROS Python and the environment it needs."""

    python: str
    env: dict[str, str]


def ros_environment() -> dict[str, str]:
    """This process's environment with the ROS PYTHONPATH as the shell had it."""
    env = dict(os.environ)
    original = env.pop(ORIGINAL, None)
    if original is not None:
        env["PYTHONPATH"] = original
    return env


def find_python(given: str | None, env: dict[str, str]) -> str:
    """The ROS 2 Python: `given`, else the one the sourced ROS's PYTHONPATH was built for."""
    if given:
        path = shutil.which(given) or given
        if not os.access(path, os.X_OK):
            raise ValueError(f"--ros2-python {given}: not an executable")
        return path
    if not env.get("ROS_DISTRO"):
        raise ValueError(_NO_ROS)
    versions = re.findall(r"python(\d+\.\d+)", env.get("PYTHONPATH", ""))
    for version in dict.fromkeys(versions):
        found = shutil.which(f"python{version}", path=env.get("PATH"))
        if found:
            return found
    return shutil.which("python3", path=env.get("PATH")) or "python3"


def probe(python: str, env: dict[str, str]) -> tuple[int, int]:
    """The Python's version, once it imported rclpy and the messages; ValueError saying why not."""
    try:
        done = subprocess.run(
            [python, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=60
        )
    except OSError as exc:
        raise ValueError(f"--ros2: cannot run {python}: {exc}") from None
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["?"])[-1]
        raise ValueError(f"{_NO_ROS}. {python} said: {last}")
    major, minor = done.stdout.split()
    return int(major), int(minor)


def _built(path: Path) -> bool:
    """A file pip or Python wrote into the sources (build/, *.egg-info, __pycache__)."""
    return any(p in ("build", "__pycache__") or p.endswith(".egg-info") for p in path.parts)


def sources_hash() -> str:
    """What the prepared folder is built from: the client library and the node's sources (not
    what an install wrote beside them: that changed the hash, and the next start installed
    again)."""
    digest = hashlib.sha256()
    for root in (CLIENTS, NODE_DIST, CLIENT_DIST):
        for path in sorted(root.rglob("*")):
            if path.is_file() and not _built(path.relative_to(root)):
                digest.update(str(path.relative_to(REPO)).encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "armfleet"


def prepare(python: str, version: tuple[int, int], env: dict[str, str]) -> Path:
    """Install the client and the node for `python` into their own folder, once per version of
    their sources (install_cache.py: shared by every checkout, server and test process)."""
    if not NODE_DIST.is_dir():
        raise ValueError(
            f"--ros2: the node's sources are not at {NODE_DIST} (a checkout is needed)"
        )
    family = f"ros-node-py{version[0]}.{version[1]}-"
    return install_cache.use(
        cache_root(),
        family + sources_hash(),
        lambda folder: _install(python, env, folder),
        family=family + "*",
    )


def _install(python: str, env: dict[str, str], target: Path) -> None:
    log.info("ROS 2 node: installing armfleet's client for %s (once)", python)
    for dist in (CLIENT_DIST, NODE_DIST):  # an earlier build's files, maybe of other sources
        shutil.rmtree(dist / "build", ignore_errors=True)
    pip = [sys.executable, "-m", "pip", "--python", python, "install", "--target", str(target)]
    steps = [[*pip, "--no-deps", str(CLIENT_DIST), str(NODE_DIST)]]
    has_deps = subprocess.run(
        [python, "-c", "import httpx, orjson, websockets.asyncio.client"],
        env=env,
        capture_output=True,
    )
    if has_deps.returncode != 0:
        steps.append([*pip, "--upgrade", *CLIENT_DEPS])
    for i, cmd in enumerate(steps, 1):
        log.info("ROS 2 node: step %d/%d: %s", i, len(steps), " ".join(cmd[3:]))
        done = subprocess.run(cmd, capture_output=True, text=True, env=_pip_env())
        if done.returncode != 0:
            tail = "\n".join(done.stderr.strip().splitlines()[-5:])
            raise ValueError(f"--ros2: installing armfleet's client for {python} failed:\n{tail}")
    log.info("ROS 2 node: installed (%s)", python)


def _pip_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return env


def node_env(given: str | None) -> NodeEnv:
    """Find the ROS 2 Python, check it, prepare the client for it: how to start the node."""
    env = ros_environment()
    python = find_python(given, env)
    version = probe(python, env)
    target = prepare(python, version, env)
    paths = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
    env["PYTHONPATH"] = os.pathsep.join([*paths, str(target)])
    env["PYTHONUNBUFFERED"] = "1"
    return NodeEnv(python, env)
