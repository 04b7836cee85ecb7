"""Every world's RTDE values at one tick, computed once for all worlds when first read.

Why in one batch: 32 ur_rtde programs stream 64 recipes at 500 Hz, and a per-world, per-read
computation (MuJoCo kinematics on a scratch MjData for each world's TCP, a lookup of the TCP
offset under the tool table's lock on every send) cost the UR thread most of its time. Here a
tick's joint rows are turned into Python lists for every world in one `tolist`, and the TCP
poses and speeds of every world come from one numpy pass over the DH chain (`URKinematics.
tcp_state`, with every world's offset read from the tool table once) — the same kinematics
`GET /v1/worlds/{w}/tcp` and getForwardKinematics answer with. A served arm that is not UR's
DH chain (a cell that changed it) has no tool table: its TCP is the flange, read with MuJoCo's
own kinematics world by world (`ToolKinematics`).

Values are renewed when the frame changes or the tool table does (a paused loop gets no new
frame, but setTcp must still show).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from service.core.errors import Unavailable
from service.core.kinematics.pose import pose_to_matrix
from service.core.kinematics.tools import ToolTable
from service.core.kinematics.ur import URKinematics
from service.core.sim.types import Snapshot
from service.surfaces.ur.tcp_pose import ARM, ToolKinematics

Rows = list[list[float]]


@dataclass(frozen=True)
class Frame:
    """What the sink hands RTDE after a tick (built on the sim thread): the snapshot, the
    target's rate of change (nworld, 7), and the tick length [s]."""

    snap: Snapshot
    target_qd: np.ndarray
    target_qdd: np.ndarray
    tick_dt: float


def _rows(a: np.ndarray) -> Rows:
    return np.asarray(a[:, :ARM], dtype=np.float64).tolist()


def _joint_rows(array: Callable[[Frame], np.ndarray]) -> cached_property[Rows]:
    """A property of `FrameValues`: the frame's `array` as one list of the arm's joints per
    world, computed once per frame. One definition for the six joint outputs, which differ
    only in the array they read (a typed accessor, not a name, so a checker sees it)."""

    def rows(values: FrameValues) -> Rows:
        return _rows(array(values.frame))

    return cached_property(rows)


class FrameValues:
    """One frame's values for every world (UR thread; each computed when first read)."""

    def __init__(
        self,
        frame: Frame,
        kin: URKinematics | None,
        offsets: tuple[int, np.ndarray | None],
        fallback: ToolKinematics,
    ) -> None:
        """kin None: the arm is not UR's DH chain (`fallback`: MuJoCo's kinematics, the flange);
        offsets: (the tool table's version, every world's TCP offset as transforms (n, 4, 4))."""
        self.frame, self._kin, self._fallback = frame, kin, fallback
        self.tcp_version, self._tcp = offsets
        self.timestamp = (frame.snap.tick * frame.tick_dt,)

    # What RTDE's joint outputs read, per world (rtde_outputs.READERS names these attributes).
    q = _joint_rows(lambda f: f.snap.position)
    qd = _joint_rows(lambda f: f.snap.velocity)
    effort = _joint_rows(lambda f: f.snap.effort)
    target = _joint_rows(lambda f: f.snap.target)
    target_qd = _joint_rows(lambda f: f.target_qd)
    target_qdd = _joint_rows(lambda f: f.target_qdd)

    @cached_property
    def actual_tcp(self) -> tuple[Rows, Rows]:
        """(poses, speeds) of every world's TCP at the measured joints."""
        if self._kin is not None:
            return self._both_tcp[0]
        snap = self.frame.snap
        return self._tcp_state(snap.position, snap.velocity)

    @cached_property
    def target_tcp(self) -> tuple[Rows, Rows]:
        """(poses, speeds) of every world's TCP at the position targets."""
        if self._kin is not None:
            return self._both_tcp[1]
        return self._tcp_state(self.frame.snap.target, self.frame.target_qd)

    @cached_property
    def _both_tcp(self) -> tuple[tuple[Rows, Rows], tuple[Rows, Rows]]:
        """actual_tcp and target_tcp of a DH arm from one pass over 2n rows. Why: a pass
        over 32 worlds costs numpy's per-call overhead far more than its rows, and ur_rtde's
        receive interface asks for both every tick (a frame's values of 32 worlds took the
        UR thread 1.4 ms of CPU with two passes, 0.9 ms with one)."""
        snap, n = self.frame.snap, len(self.frame.snap.position)
        q = np.concatenate([snap.position[:, :ARM], snap.target[:, :ARM]]).astype(np.float64)
        qd = np.concatenate([snap.velocity[:, :ARM], self.frame.target_qd[:, :ARM]])
        tcp = self._tcp
        if tcp is not None:
            tcp = np.concatenate([tcp, tcp])
        assert self._kin is not None
        pose, speed = self._kin.tcp_state(q, qd.astype(np.float64), tcp)
        p, v = pose.tolist(), speed.tolist()
        return (p[:n], v[:n]), (p[n:], v[n:])

    def _tcp_state(self, q: np.ndarray, qd: np.ndarray) -> tuple[Rows, Rows]:
        q = np.asarray(q[:, :ARM], dtype=np.float64)
        qd = np.asarray(qd[:, :ARM], dtype=np.float64)
        if self._kin is not None:
            pose, speed = self._kin.tcp_state(q, qd, self._tcp)
            return pose.tolist(), speed.tolist()
        rows = [self._fallback.tcp(q[w], qd[w], (0.0,) * 6) for w in range(len(q))]
        return [p.tolist() for p, _ in rows], [s.tolist() for _, s in rows]


class FrameValuesCache:
    """The latest frame's `FrameValues`, renewed when the frame or the tool table moves."""

    def __init__(self, fallback: ToolKinematics, tools: Callable[[], ToolTable | None]) -> None:
        self._fallback, self._tools_of = fallback, tools
        self._tools: ToolTable | None = None
        self._resolved = False
        self._values: FrameValues | None = None
        self._offsets: tuple[int, np.ndarray | None] = (-1, None)

    def get(self, frame: Frame | None) -> FrameValues | None:
        if frame is None:
            return None
        tools = self._table()
        version = -1 if tools is None else tools.version
        v = self._values
        if v is None or v.frame is not frame or v.tcp_version != version:
            if tools is not None and self._offsets[0] != version:
                version, offsets = tools.all()
                self._offsets = (version, pose_to_matrix(offsets))
            kin = None if tools is None else tools.kin
            v = self._values = FrameValues(frame, kin, self._offsets, self._fallback)
        return v

    def _table(self) -> ToolTable | None:
        """The loop's tool table, looked up once: `tools` answers None while it cannot tell
        yet (the surface not started) and Unavailable when the arm has no UR kinematics."""
        if not self._resolved:
            try:
                self._tools = self._tools_of()
                self._resolved = self._tools is not None
            except Unavailable:
                self._tools, self._resolved = None, True
        return self._tools
