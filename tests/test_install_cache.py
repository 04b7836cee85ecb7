"""The ROS node's install cache (service/surfaces/ros/install_cache.py), shared by every
checkout and test process: separate processes (as two worktrees, or xdist workers, are) build
and use versions side by side; none deletes or half-writes a folder another uses. The build is
a few file writes here: what is under test is the folders, the locks and the renames, not pip.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from service.surfaces.ros import install_cache

FAMILY = "ros-node-py3.11-*"
# One process using `name`: its build writes a file, counts itself in builds.log and sleeps
# `slow` s (a pip install takes that long or longer); after `use` it says where it got, then
# holds the folder until its stdin closes (a server, for its node's life).
USER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from service.surfaces.ros import install_cache

    root, name, slow = Path(sys.argv[1]), sys.argv[2], float(sys.argv[3])

    def build(folder):
        with open(root / "builds.log", "a") as log:
            log.write(name + "\\n")
        (folder / "armfleet_ros").mkdir()
        if slow < 0:
            raise RuntimeError("the build failed")
        time.sleep(slow)
        (folder / "armfleet_ros" / "node.py").write_text(name)

    target = install_cache.use(root, name, build, family="ros-node-py3.11-*")
    print(target, flush=True)
    sys.stdin.read()
    print((target / "armfleet_ros" / "node.py").read_text(), flush=True)
    """
)


def start(root: Path, name: str, slow: float = 0.0) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", USER, str(root), name, str(slow)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).resolve().parents[1],
    )


def finish(p: subprocess.Popen[str]) -> list[str]:
    """Let the user go; what it printed (its folder, then its node file as it read it last)."""
    out, err = p.communicate("", timeout=120)
    assert p.returncode == 0, err
    return out.split()


def builds(root: Path) -> list[str]:
    log = root / "builds.log"
    return log.read_text().split() if log.exists() else []


def age(folder: Path, days: float) -> None:
    then = time.time() - days * 24 * 3600
    os.utime(folder / install_cache.STAMP, (then, then))


def test_two_checkouts_build_their_versions_at_once_and_neither_deletes_the_other(tmp_path):
    users = [start(tmp_path, f"ros-node-py3.11-{h}", slow=0.5) for h in ("aaaa", "bbbb")]
    seen = [finish(p) for p in users]
    for (folder, content), h in zip(seen, ("aaaa", "bbbb"), strict=True):
        assert folder == str(tmp_path / f"ros-node-py3.11-{h}")
        assert content == f"ros-node-py3.11-{h}"  # still there when the user read it last
    assert sorted(builds(tmp_path)) == ["ros-node-py3.11-aaaa", "ros-node-py3.11-bbbb"]
    assert not list(tmp_path.glob(".ros-node-*"))  # no temporary folder left


def test_workers_asking_for_one_version_at_once_build_it_once(tmp_path):
    users = [start(tmp_path, "ros-node-py3.11-cccc", slow=0.3) for _ in range(3)]
    seen = [finish(p) for p in users]
    assert builds(tmp_path) == ["ros-node-py3.11-cccc"]
    assert all(s == [str(tmp_path / "ros-node-py3.11-cccc"), "ros-node-py3.11-cccc"] for s in seen)


def test_an_old_version_is_removed_only_when_nobody_uses_it(tmp_path):
    held = start(tmp_path, "ros-node-py3.11-held")
    assert held.stdout is not None
    assert held.stdout.readline().strip().endswith("held")  # built, and in use from now on
    finish(start(tmp_path, "ros-node-py3.11-idle"))
    finish(start(tmp_path, "ros-node-py3.11-new1"))
    for name in ("held", "idle", "new1"):
        age(tmp_path / f"ros-node-py3.11-{name}", days=30)
    (tmp_path / "ros-node-py3.11-new1" / install_cache.STAMP).touch()  # used just now

    finish(start(tmp_path, "ros-node-py3.11-new2"))  # a new version's build prunes

    left = sorted(p.name for p in tmp_path.glob(FAMILY) if p.is_dir())
    assert left == ["ros-node-py3.11-held", "ros-node-py3.11-new1", "ros-node-py3.11-new2"]
    assert finish(held)[-1] == "ros-node-py3.11-held"  # its user read its folder to the end


def test_a_failed_or_dead_build_leaves_nothing_under_the_name_and_the_next_use_builds(tmp_path):
    failed = start(tmp_path, "ros-node-py3.11-dddd", slow=-1)
    failed.communicate("", timeout=120)
    assert failed.returncode != 0
    assert not (tmp_path / "ros-node-py3.11-dddd").exists()
    # what a build killed mid-way leaves (its temporary folder), and a folder an earlier
    # layout half wrote in place (no stamp)
    (tmp_path / ".ros-node-py3.11-eeee.tmp-x1").mkdir()
    (tmp_path / "ros-node-py3.11-dddd").mkdir()
    (tmp_path / "ros-node-py3.11-dddd" / "stale").write_text("half")

    assert finish(start(tmp_path, "ros-node-py3.11-dddd"))[-1] == "ros-node-py3.11-dddd"
    assert not (tmp_path / "ros-node-py3.11-dddd" / "stale").exists()
    assert not (tmp_path / ".ros-node-py3.11-eeee.tmp-x1").exists()
    assert builds(tmp_path) == ["ros-node-py3.11-dddd", "ros-node-py3.11-dddd"]


def test_the_sources_hash_ignores_what_an_install_writes_beside_the_sources(tmp_path, monkeypatch):
    from service.surfaces.ros import node_env

    for folder, name in (("clients", "client.py"), ("node/armfleet_ros", "node.py")):
        (tmp_path / folder).mkdir(parents=True)
        (tmp_path / folder / name).write_text("one = 1\n")
    (tmp_path / "dist").mkdir()
    (tmp_path / "dist" / "pyproject.toml").write_text("[project]\n")
    monkeypatch.setattr(node_env, "REPO", tmp_path)
    monkeypatch.setattr(node_env, "CLIENTS", tmp_path / "clients")
    monkeypatch.setattr(node_env, "NODE_DIST", tmp_path / "node")
    monkeypatch.setattr(node_env, "CLIENT_DIST", tmp_path / "dist")
    before = node_env.sources_hash()
    for written in (  # what pip's in-tree build and Python leave there
        "node/build/lib/armfleet_ros/node.py",
        "node/armfleet_ros.egg-info/PKG-INFO",
        "dist/armfleet_client.egg-info/PKG-INFO",
        "clients/__pycache__/client.cpython-311.pyc",
    ):
        (tmp_path / written).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / written).write_text("built\n")
    assert node_env.sources_hash() == before
    (tmp_path / "node/armfleet_ros/node.py").write_text("one = 2\n")
    assert node_env.sources_hash() != before
