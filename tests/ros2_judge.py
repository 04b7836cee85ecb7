"""The real ROS 2 that judges armfleet_ros: Jazzy's rclpy + rmw_fastrtps_cpp from
../shared/ros2_judge, built once per version of its sources into ~/.cache/armfleet.

    python -m tests.ros2_judge          # build it if missing (about 3-4 min), print its folder

Found at: $ARMFLEET_ROS2_JUDGE, else ~/.cache/armfleet/ros2-judge-<hash of the sources>, else
the setup script's own default (/tmp/ros2-judge). Each test process gets ROS_DOMAIN_IDs of its
own (claimed with a lock file, below 230: Fast DDS refuses higher) and LOCALHOST discovery, so
pytest-xdist workers and runs side by side never see each other and nothing leaves the machine.
The build takes a lock too: two processes that find it missing build it once.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NODE_SRC = ROOT / "packaging" / "armfleet-ros"
JUDGE_SCRIPT = Path(__file__).resolve().parent / "rclpy" / "judge.py"


def sources() -> Path | None:
    """The judge's sources (setup.sh and the interface tarball) beside the checkout."""
    given = os.environ.get("ARMFLEET_ROS2_JUDGE_SRC")
    candidates = [Path(given)] if given else []
    candidates += [p / "shared" / "ros2_judge" for p in ROOT.parents]
    return next((c for c in candidates if (c / "setup.sh").is_file()), None)


def sources_hash(src: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(src.rglob("*")):
        if path.is_file():
            digest.update(path.name.encode() + path.read_bytes())
    return digest.hexdigest()[:12]


def cached_root(src: Path) -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "armfleet" / f"ros2-judge-{sources_hash(src)}"


def root() -> Path | None:
    """A built judge (its env.sh exists), or None."""
    given = os.environ.get("ARMFLEET_ROS2_JUDGE")
    src = sources()
    options = [Path(given)] if given else []
    if src is not None:
        options.append(cached_root(src))
    options.append(Path("/tmp/ros2-judge"))
    return next((o for o in options if (o / "env.sh").is_file()), None)


def skip_reason() -> str | None:
    if root() is not None:
        return None
    if sources() is None:
        return "no ROS 2 judge: ../shared/ros2_judge not found beside the checkout"
    return "the ROS 2 judge is not built: run `python -m tests.ros2_judge` (or scripts/dev.py test)"


DOMAINS = range(20, 220)
_claimed: dict[int, int] = {}  # offset -> the domain this process holds for it
_held: list[object] = []  # the claims' open lock files, released when the process ends


def domain_id(offset: int = 0) -> int:
    """This test process's ROS_DOMAIN_ID: 20..219 (`offset`: another graph of the same process,
    for a test that must not see the module's node). Each is claimed once, starting from the
    pid, by locking a file of that number: a domain another live process holds (an xdist
    worker, a run beside this one) is passed over, so no two graphs meet."""
    if offset not in _claimed:
        folder = Path(tempfile.gettempdir()) / "armfleet-ros-domains"
        folder.mkdir(exist_ok=True)
        start = (os.getpid() + offset) % len(DOMAINS)
        for i in range(len(DOMAINS)):
            domain = DOMAINS[(start + i) % len(DOMAINS)]
            if domain in _claimed.values():
                continue
            lock = open(folder / f"{domain}.lock", "w")  # noqa: SIM115 (held until exit)
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                lock.close()
                continue
            _held.append(lock)
            _claimed[offset] = domain
            break
        else:
            raise RuntimeError(f"every ROS domain of {DOMAINS} is held by another process")
    return _claimed[offset]


@cache
def env() -> dict[str, str]:
    """The environment of a shell that sourced the judge's env.sh, on this process's domain."""
    r = root()
    assert r is not None
    dump = subprocess.run(
        ["bash", "-c", f'source "{r}/env.sh" >/dev/null && env -0'],
        capture_output=True,
        check=True,
    ).stdout
    out = dict(item.split("=", 1) for item in dump.decode().split("\0") if "=" in item)
    out["ROS_DOMAIN_ID"] = str(domain_id())
    out["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    out.setdefault("ROS_DISTRO", "jazzy")
    return out


def python() -> str:
    r = root()
    assert r is not None
    return str(r / "venv" / "bin" / "python")


def on_domain(e: dict[str, str], offset: int) -> dict[str, str]:
    return {**e, "ROS_DOMAIN_ID": str(domain_id(offset))}


def node_env() -> dict[str, str]:
    """The judge's environment with the node, the client and its dependencies importable, as
    `armfleet serve --ros2` prepares them (pip for the judge's Python, into ~/.cache/armfleet)."""
    from service.surfaces.ros import node_env as prepared

    e = dict(env())
    target = prepared.prepare(python(), prepared.probe(python(), e), e)
    e["PYTHONPATH"] = os.pathsep.join([e.get("PYTHONPATH", ""), str(target)])
    e["PYTHONUNBUFFERED"] = "1"
    return e


def build() -> Path:
    src = sources()
    if src is None:
        raise SystemExit("../shared/ros2_judge not found")
    target = cached_root(src)
    if (target / "env.sh").is_file():
        return target
    with _locked(target.with_name(target.name + ".lock")):  # one build, whoever else asks
        if not (target / "env.sh").is_file():
            print(f"building the ROS 2 judge into {target} (about 3-4 min, once)", flush=True)
            env = {**os.environ, "RJ_ROOT": str(target)}
            subprocess.run(["bash", str(src / "setup.sh")], env=env, check=True)
    return target


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on `path` (waiting for another holder) for the block."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


if __name__ == "__main__":
    print(build())
    sys.exit(0)
