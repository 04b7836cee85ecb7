"""A cache of installed folders, one per version of their sources, shared by every checkout.

The ROS node's install (node_env.py) lives under ~/.cache/armfleet, which every checkout, server
and pytest-xdist worker of the user shares, each possibly on other sources: a worktree with an
edited node installs beside main's, and neither may delete or half-write the other's folder
while a node runs from it. So:

- each version is a folder of its own, `<name>` (the name carries the sources' hash), complete
  once it exists: it is built in a temporary folder beside it and renamed into place (atomic),
  so nobody sees it half written, and a build that crashed leaves only a temporary folder;
- one build per name at a time (`<name>.build.lock`, exclusive): the others wait and use it;
  builds of other names run in parallel;
- whoever uses a folder holds `<name>.use.lock` shared for as long as its process lives (a
  server, for its node's life), and refreshes the folder's last-use time;
- another version's folder is removed only when it was not used for KEEP_S and nobody holds its
  use lock (taken exclusive without waiting, else left alone): renamed aside first, so a user
  never finds a half-deleted folder under its name.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO

KEEP_S = 7 * 24 * 3600.0  # another version's folder, unused this long, is removed
STAMP = ".complete"  # in a finished folder; its mtime is the last use
_TMP = ".tmp-"  # temporary folders: `.<name>.tmp-XXXX` (a build) or `.<name>.old-XXXX` (a removal)
_OLD = ".old-"
_held: list[IO[str]] = []  # this process's use locks, released when it ends


def _lock_file(path: Path) -> IO[str]:
    return open(path, "a")  # the caller holds it


@contextlib.contextmanager
def _exclusive(path: Path) -> Iterator[None]:
    with _lock_file(path) as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        yield


def use(root: Path, name: str, build: Callable[[Path], None], family: str) -> Path:
    """`root/name`, built by `build(folder)` once if missing, and held in use by this process.
    Other folders of `family` (a glob of names, e.g. `ros-node-py3.11-*`) not used for KEEP_S
    and held by nobody are removed."""
    root.mkdir(parents=True, exist_ok=True)
    target = root / name
    held = _lock_file(root / f"{name}.use.lock")
    fcntl.flock(held, fcntl.LOCK_SH)  # a removal of this folder in progress finishes first
    try:
        if not (target / STAMP).exists():
            with _exclusive(root / f"{name}.build.lock"):
                if not (target / STAMP).exists():
                    _build(root, name, build)
                    prune(root, family, keep=name)
        os.utime(target / STAMP)  # the last use: what prune reads
    except BaseException:
        held.close()
        raise
    _held.append(held)
    return target


def _build(root: Path, name: str, build: Callable[[Path], None]) -> None:
    target = root / name
    if target.exists():  # no stamp: an earlier layout's half install, or a crashed one
        _set_aside(root, name)
    tmp = Path(tempfile.mkdtemp(prefix=f".{name}{_TMP}", dir=root))
    try:
        build(tmp)
        (tmp / STAMP).write_text(f"{time.time()}\n")
        os.rename(tmp, target)  # atomic: the folder appears whole or not at all
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _set_aside(root: Path, name: str) -> None:
    """Rename `root/name` out of the way, then delete it."""
    aside = Path(tempfile.mkdtemp(prefix=f".{name}{_OLD}", dir=root))
    os.rename(root / name, aside / name)
    shutil.rmtree(aside, ignore_errors=True)


def prune(root: Path, family: str, keep: str, keep_s: float = KEEP_S) -> list[str]:
    """Remove the folders of `family` other than `keep` unused for `keep_s` and held by nobody,
    and temporary folders of builds that died; the names removed."""
    removed: list[str] = []
    now = time.time()
    for folder in sorted(root.glob(family)):
        name = folder.name
        if name == keep or not folder.is_dir():
            continue
        stamp = folder / STAMP
        with contextlib.suppress(FileNotFoundError):
            if stamp.exists() and now - stamp.stat().st_mtime < keep_s:
                continue
            if _if_unheld(root / f"{name}.use.lock", lambda n=name: _set_aside(root, n)):
                removed.append(name)
    for tmp in root.glob(f".{family}"):
        name, sep, _ = tmp.name[1:].partition(_TMP)
        if not sep:
            name, sep, _ = tmp.name[1:].partition(_OLD)
        # a build in progress holds its build lock: only a dead one's folder goes
        if sep and _if_unheld(root / f"{name}.build.lock", lambda t=tmp: shutil.rmtree(t)):
            removed.append(tmp.name)
    return removed


def _if_unheld(lock: Path, act: Callable[[], None]) -> bool:
    """Run `act` holding `lock` exclusive, if nobody holds it now; whether it ran."""
    with _lock_file(lock) as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return False
        with contextlib.suppress(FileNotFoundError):
            act()
            return True
        return False
