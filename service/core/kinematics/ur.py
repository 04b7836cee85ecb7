"""The UR10e's kinematics, read from the served model: flange and TCP poses, Jacobian and the
closed-form inverse, for all worlds at once.

Why the closed form (UR's own, as in Hawkins, "Analytic Inverse Kinematics for the Universal
Robots UR-5/UR-10 Arms", 2013) over a numerical solver (mink, pinocchio, ikpy): the served arm
*is* UR's DH chain (`from_model` reads d1, a2, a3, d4, d5, d6 off the model and refuses a model
whose joints do not reproduce it to 1e-9 m under `mj_kinematics`), so the closed form is exact
to rounding, gives all eight configurations at once (shoulder left/right, elbow up/down, wrist
flipped or not) with no iterations, no starting guess and no local minima, and vectorises over
worlds as plain numpy; a UR controller answers `get_inverse_kin` the same way (the solution
nearest a given q). A numerical solver would add a dependency, iterate per world, and could only
find one configuration near its seed.

Frames. Poses are in the robot's *base frame*, as a UR reports them: the model's `base` body
(ROS base_link_inertia = UR's DH frame 0: z up along the shoulder axis, x pointing away from
the shoulder's cable side; in the served scene it sits at world (0, 0, 0.5) turned π about z,
so base x = -world x, base y = -world y, base z = world z - 0.5; `base_in_world` holds it for
any cell). The flange is the model's `flange` site (= DH frame 6 = ROS tool0: z out of the tool
flange). The TCP is the flange composed with a per-world offset given as UR's `set_tcp` takes
it, p[x, y, z, rx, ry, rz] in the flange frame.

Unreachable poses and singularities: `ik` answers every world; `IKResult.ok` says which got a
solution, `IKResult.reason` says why not (`OUT_OF_REACH`: no configuration reaches the pose;
`JOINT_LIMITS`: some do, none inside the joint ranges), and `IKResult.singular` names the
chosen solution's singularity (`WRIST` sin θ5 ≈ 0, `ELBOW` sin θ3 ≈ 0, `SHOULDER`: the wrist
centre over the shoulder axis). At a wrist singularity θ6 is not determined; the solver keeps
the given q's θ6 there.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from service.core.kinematics.pose import cross, invert, matrix_to_pose, pose_to_matrix

__all__ = ["IKResult", "NotDH", "Singularity", "URKinematics", "Unsolved"]

TWO_PI = 2.0 * np.pi
_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])
_CHECK_TOL = 1e-9  # m and rad: how exactly the model must reproduce the DH chain
_SOLVE_TOL = 1e-7  # m and rad: an IK candidate farther than this from the pose is not one
_CLAMP = 1e-9  # slack on |cos| <= 1 (a pose exactly at full reach still solves)
_SINGULAR = 1e-6  # below this, a singularity factor counts as singular


class NotDH(ValueError):
    """The model's arm does not reproduce UR's DH chain: the closed-form IK does not apply."""


class Unsolved:
    """Why `ik` found no solution for a world (`IKResult.reason`)."""

    OK, OUT_OF_REACH, JOINT_LIMITS = 0, 1, 2
    NAMES = ("ok", "out_of_reach", "joint_limits")


class Singularity:
    """Bits of `IKResult.singular` / `URKinematics.singularity`: which singularity a q is at."""

    NONE, WRIST, ELBOW, SHOULDER = 0, 1, 2, 4

    @staticmethod
    def names(bits: int) -> list[str]:
        return [n for b, n in ((1, "wrist"), (2, "elbow"), (4, "shoulder")) if bits & b]


@dataclass(frozen=True)
class IKResult:
    """`ik`'s answer for n worlds.

    q: the solution nearest q_near [rad]; q_near's row where there is none         (n, 6)
    ok: a solution was found                                                       (n,) bool
    reason: Unsolved.OK / OUT_OF_REACH / JOINT_LIMITS                              (n,) int
    singular: Singularity bits of the chosen solution (0: none)                    (n,) int
    """

    q: np.ndarray
    ok: np.ndarray
    reason: np.ndarray
    singular: np.ndarray

    def why(self, i: int) -> str:
        return Unsolved.NAMES[int(self.reason[i])]


@dataclass(frozen=True)
class URKinematics:
    """UR DH kinematics of one model. `d`, `a`: (6,) DH lengths [m] (d2 = d3 = a1 = a4..a6 = 0);
    `lower`, `upper`: (6,) joint ranges [rad]; `flange_in_dh6`, `base_in_world`: (4, 4)."""

    d: np.ndarray
    a: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    flange_in_dh6: np.ndarray
    base_in_world: np.ndarray

    # -- building it from the model ---------------------------------------------------------

    @classmethod
    def from_model(
        cls, mjm: mujoco.MjModel, joints: Sequence[str], flange_site: str = "flange"
    ) -> URKinematics:
        """Read the DH lengths off `mjm` (joint anchors at q = 0 in the base frame), then check
        at random q that the DH chain gives `mj_kinematics`' flange pose; NotDH if not."""
        ids = [mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joints]
        site = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_SITE, flange_site)
        if len(ids) != 6 or min(ids) < 0 or site < 0:
            raise NotDH(f"need six arm joints and the site {flange_site!r}, got {list(joints)}")
        base = int(mjm.body_parentid[mjm.jnt_bodyid[ids[0]]])
        b = base
        while b:  # the base must be welded to the world: its pose is the same in every state
            if mjm.body_dofnum[b]:
                raise NotDH("the arm's base moves (it has joints above it)")
            b = int(mjm.body_parentid[b])
        data = mujoco.MjData(mjm)
        adr = mjm.jnt_qposadr[ids]

        def model_fk(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            data.qpos[:] = mjm.qpos0
            data.qpos[adr] = q
            mujoco.mj_kinematics(mjm, data)
            tb = _transform(data.xpos[base], data.xmat[base])
            tf = _transform(data.site_xpos[site], data.site_xmat[site])
            anchors = (invert(tb) @ np.c_[data.xanchor[ids], np.ones(6)].T).T[:, :3]
            return tb, invert(tb) @ tf, anchors

        tb, flange0, anc = model_fk(np.zeros(6))
        d1, a2 = anc[1, 2], anc[2, 0]
        a3, d4 = anc[3, 0] - a2, -anc[4, 1]
        d5 = d1 - anc[5, 2]
        d6 = -flange0[1, 3] - d4
        d = np.array([d1, 0.0, 0.0, d4, d5, d6])
        a = np.array([0.0, a2, a3, 0.0, 0.0, 0.0])
        lower, upper = mjm.jnt_range[ids, 0].copy(), mjm.jnt_range[ids, 1].copy()
        unlimited = ~mjm.jnt_limited[ids].astype(bool)
        lower[unlimited], upper[unlimited] = -np.inf, np.inf
        dh6 = _chain(d, a, np.zeros((1, 6)))[0]
        kin = cls(d, a, lower, upper, invert(dh6) @ flange0, tb)
        rng = np.random.default_rng(0)
        for q in rng.uniform(-np.pi, np.pi, (16, 6)):
            _, want, _ = model_fk(q)
            got = kin.flange(q[None])[0]
            err = np.abs(got - want).max()
            if err > _CHECK_TOL:
                raise NotDH(f"the model's flange is {err:.3g} from UR's DH chain at q={q}")
        return kin

    # -- forward ----------------------------------------------------------------------------

    def flange(self, q: np.ndarray) -> np.ndarray:
        """Flange transforms in the base frame (n, 4, 4) at arm joint angles q (n, 6) [rad]."""
        return _chain(self.d, self.a, np.asarray(q, dtype=np.float64)) @ self.flange_in_dh6

    def frames(self, q: np.ndarray) -> np.ndarray:
        """DH frames 0..6 in the base frame (n, 7, 4, 4) at q (n, 6): frame i moves with
        joint i (1-based), frame 6 with the flange."""
        return _frames(self.d, self.a, np.asarray(q, dtype=np.float64))

    def tcp(self, q: np.ndarray, tcp: np.ndarray | None = None) -> np.ndarray:
        """TCP transforms in the base frame (n, 4, 4); tcp: offsets (n, 6) or (6,), None: 0."""
        t = self.flange(q)
        return t if tcp is None else t @ pose_to_matrix(tcp)

    def fk(self, q: np.ndarray, tcp: np.ndarray | None = None) -> np.ndarray:
        """UR poses p[x, y, z, rx, ry, rz] of the TCP in the base frame (n, 6), as
        getActualTCPPose / get_forward_kin answer; tcp None: the flange's."""
        return matrix_to_pose(self.tcp(q, tcp))

    def to_world(self, t: np.ndarray) -> np.ndarray:
        """Base-frame transforms (n, 4, 4) in MuJoCo's world frame."""
        return self.base_in_world @ t

    def jacobian(self, q: np.ndarray, tcp: np.ndarray | None = None) -> np.ndarray:
        """Geometric Jacobians (n, 6, 6) at the TCP, base frame: rows vx vy vz wx wy wz
        (speedL's tool speed), columns the joints' speeds."""
        q = np.asarray(q, dtype=np.float64)
        frames = _frames(self.d, self.a, q)  # (n, 7, 4, 4): frame 0..6
        p = self.tcp(q, tcp)[:, :3, 3]
        z = frames[:, :6, :3, 2]
        o = frames[:, :6, :3, 3]
        jv = np.cross(z, p[:, None, :] - o)
        return np.concatenate([jv, z], axis=-1).transpose(0, 2, 1)

    def tcp_state(
        self, q: np.ndarray, qd: np.ndarray, tcp: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(TCP poses p[x, y, z, rx, ry, rz] (n, 6), TCP speeds vx vy vz wx wy wz (n, 6)) in the
        base frame at q (n, 6) moving at qd (n, 6), as RTDE's actual_TCP_pose/_speed report
        them: `fk` and `jacobian` @ qd from one pass over the DH frames (RTDE asks every tick
        for every streaming world). tcp: offsets as poses (n, 6) or as transforms (n, 4, 4)
        (a caller that keeps them between ticks converts them once)."""
        q = np.asarray(q, dtype=np.float64)
        qd = np.asarray(qd, dtype=np.float64)
        frames = _frames(self.d, self.a, q)  # (n, 7, 4, 4)
        t = frames[:, 6] @ self.flange_in_dh6
        if tcp is not None:
            tcp = np.asarray(tcp, dtype=np.float64)
            t = t @ (tcp if tcp.shape[-2:] == (4, 4) else pose_to_matrix(tcp))
        z = frames[:, :6, :3, 2]  # joint axes (n, 6, 3)
        lever = t[:, None, :3, 3] - frames[:, :6, :3, 3]
        v = np.einsum("nj,njk->nk", qd, cross(z, lever))
        w = np.einsum("nj,njk->nk", qd, z)
        return matrix_to_pose(t), np.concatenate([v, w], axis=-1)

    def singularity(self, q: np.ndarray) -> np.ndarray:
        """Singularity bits (n,) of q (n, 6): the factors of det J = a2 a3 s3 s5 (a2 c2 + a3 c23
        + d5 s234) near zero (lengths normalised by the arm's reach)."""
        q = np.asarray(q, dtype=np.float64)
        a2, a3, d5 = self.a[1], self.a[2], self.d[4]
        reach = abs(a2) + abs(a3)
        s234 = np.sin(q[:, 1] + q[:, 2] + q[:, 3])
        arm = (a2 * np.cos(q[:, 1]) + a3 * np.cos(q[:, 1] + q[:, 2]) + d5 * s234) / reach
        bits = np.where(np.abs(np.sin(q[:, 4])) < _SINGULAR, Singularity.WRIST, 0)
        bits |= np.where(np.abs(np.sin(q[:, 2])) < _SINGULAR, Singularity.ELBOW, 0)
        return bits | np.where(np.abs(arm) < _SINGULAR, Singularity.SHOULDER, 0)

    # -- inverse ----------------------------------------------------------------------------

    def ik_all(
        self, pose: np.ndarray, tcp: np.ndarray | None = None, q6: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """All eight closed-form solutions for TCP poses (n, 6) in the base frame.

        Returns (q (n, 8, 6) with angles in (-π, π], valid (n, 8)): a solution is valid when
        its flange pose is within 1e-7 of the asked one. `q6` (n,): θ6 where the wrist is
        singular (sin θ5 ≈ 0), default 0."""
        return self.solutions(pose_to_matrix(pose), tcp, q6)

    def solutions(
        self, t: np.ndarray, tcp: np.ndarray | None = None, q6: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """`ik_all` for TCP transforms (n, 4, 4) in the base frame."""
        if tcp is not None:
            t = t @ invert(pose_to_matrix(tcp))
        return self._solve(t @ invert(self.flange_in_dh6), q6)

    def ik(self, pose: np.ndarray, q_near: np.ndarray, tcp: np.ndarray | None = None) -> IKResult:
        """The solution nearest q_near (n, 6) for TCP poses (n, 6), each joint taken to the
        turn (θ + 2πk) nearest q_near inside its range; see `IKResult`."""
        pose = np.asarray(pose, dtype=np.float64)
        q_near = np.asarray(q_near, dtype=np.float64)
        sols, valid = self.ik_all(pose, tcp, q_near[:, 5])
        cand = _nearest_turn(sols, q_near[:, None, :], self.lower, self.upper)
        inside = ((cand >= self.lower) & (cand <= self.upper)).all(axis=-1)
        usable = valid & inside
        cost = np.where(usable, ((cand - q_near[:, None, :]) ** 2).sum(-1), np.inf)
        best = np.argmin(cost, axis=1)
        ok = usable.any(axis=1)
        q = np.where(ok[:, None], cand[np.arange(len(q_near)), best], q_near)
        reason = np.where(ok, Unsolved.OK, np.where(valid.any(1), Unsolved.JOINT_LIMITS, 1))
        singular = np.where(ok, self.singularity(q), 0)
        return IKResult(q, ok, reason.astype(np.int64), singular.astype(np.int64))

    def _solve(self, t06: np.ndarray, q6: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        d1, d4, d5, d6 = self.d[0], self.d[3], self.d[4], self.d[5]
        a2, a3 = self.a[1], self.a[2]
        n = len(t06)
        r, p6 = t06[:, :3, :3], t06[:, :3, 3]
        p5 = p6 - d6 * r[:, :, 2]  # the wrist centre (origin of frame 5)
        # θ1: the wrist centre lies d4 off the arm's plane: ρ sin(θ1 - ψ) = d4 (two branches)
        rho = np.hypot(p5[:, 0], p5[:, 1])
        psi = np.arctan2(p5[:, 1], p5[:, 0])
        ratio = d4 / np.maximum(rho, 1e-300)
        ok1 = ratio <= 1 + _CLAMP
        phi = np.arcsin(np.clip(ratio, -1, 1))
        th1 = np.stack([psi + phi, psi + np.pi - phi], 1)  # (n, 2)
        s1, c1 = np.sin(th1), np.cos(th1)
        # θ5: the flange's offset along z1 = (s1, -c1, 0) is d4 + d6 cos θ5
        c5 = (p6[:, None, 0] * s1 - p6[:, None, 1] * c1 - d4) / d6
        ok5 = np.abs(c5) <= 1 + _CLAMP
        th5a = np.arccos(np.clip(c5, -1, 1))
        th5 = np.stack([th5a, -th5a], 2)  # (n, 2, 2)
        s5 = np.sin(th5)
        # θ6: z1 seen from frame 6 is (s5 c6, -s5 s6, c5)
        ux = r[:, None, 0, 0] * s1 - r[:, None, 1, 0] * c1
        uy = r[:, None, 0, 1] * s1 - r[:, None, 1, 1] * c1
        free = np.zeros(n) if q6 is None else np.asarray(q6, dtype=np.float64)
        wrist = np.abs(s5) < _SINGULAR
        safe = np.where(wrist, 1.0, s5)
        th6 = np.where(
            wrist, free[:, None, None], np.arctan2(-uy[..., None] / safe, ux[..., None] / safe)
        )
        # θ2, θ3, θ4 in the arm's plane: T14 = A1⁻¹ T06 (A5 A6)⁻¹
        th1b = np.broadcast_to(th1[:, :, None], th5.shape)
        a1 = _dh(th1b, d1, 0.0, _ALPHA[0])
        a56 = _dh(th5, d5, 0.0, _ALPHA[4]) @ _dh(th6, d6, 0.0, _ALPHA[5])
        t14 = invert(a1) @ t06[:, None, None] @ invert(a56)
        x, y = t14[..., 0, 3], t14[..., 1, 3]
        c3 = (x**2 + y**2 - a2**2 - a3**2) / (2 * a2 * a3)
        ok3 = np.abs(c3) <= 1 + _CLAMP
        th3a = np.arccos(np.clip(c3, -1, 1))
        th3 = np.stack([th3a, -th3a], 3)  # (n, 2, 2, 2)
        th2 = np.arctan2(y, x)[..., None] - np.arctan2(a3 * np.sin(th3), a2 + a3 * np.cos(th3))
        th234 = np.arctan2(t14[..., 1, 0], t14[..., 0, 0])[..., None]
        th4 = th234 - th2 - th3
        shape = th3.shape
        q = np.stack(
            [
                np.broadcast_to(th1[:, :, None, None], shape),
                th2,
                th3,
                th4,
                np.broadcast_to(th5[..., None], shape),
                np.broadcast_to(th6[..., None], shape),
            ],
            -1,
        ).reshape(n, 8, 6)
        q = _wrap(q)
        reached = (
            np.broadcast_to(ok1[:, None, None, None], shape)
            & np.broadcast_to(ok5[..., None, None], shape)
            & np.broadcast_to(ok3[..., None], shape)
        ).reshape(n, 8)
        got = _chain(self.d, self.a, q.reshape(-1, 6)).reshape(n, 8, 4, 4)
        err = np.abs(got - t06[:, None]).max(axis=(-1, -2))
        return q, reached & (err < _SOLVE_TOL) & np.isfinite(q).all(-1)


# -- the DH chain -----------------------------------------------------------------------------


def _dh(theta: np.ndarray, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH transforms Rz(θ) Tz(d) Tx(a) Rx(α) for angles θ (...) → (..., 4, 4)."""
    c, s = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    out = np.zeros((*np.shape(theta), 4, 4))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2], out[..., 0, 3] = c, -s * ca, s * sa, a * c
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2], out[..., 1, 3] = s, c * ca, -c * sa, a * s
    out[..., 2, 1], out[..., 2, 2], out[..., 2, 3] = sa, ca, d
    out[..., 3, 3] = 1.0
    return out


def _frames(d: np.ndarray, a: np.ndarray, q: np.ndarray) -> np.ndarray:
    """DH frames 0..6 in the base frame (n, 7, 4, 4): each link is Rz(θ) then a constant
    Tz(d) Tx(a) Rx(α), so the six turns are built in one pass and the constants multiplied in
    one batched product (the per-tick clearance watch runs this for every moving world)."""
    n = len(q)
    c, s = np.cos(q), np.sin(q)
    turn = np.zeros((n, 6, 4, 4))
    turn[..., 0, 0], turn[..., 0, 1], turn[..., 1, 0], turn[..., 1, 1] = c, -s, s, c
    turn[..., 2, 2] = turn[..., 3, 3] = 1.0
    link = turn @ _dh(np.zeros(6), d, a, _ALPHA)  # (n, 6, 4, 4)
    out = np.empty((n, 7, 4, 4))
    out[:, 0] = np.eye(4)
    for i in range(6):
        out[:, i + 1] = out[:, i] @ link[:, i]
    return out


def _chain(d: np.ndarray, a: np.ndarray, q: np.ndarray) -> np.ndarray:
    """DH frame 6 in the base frame (n, 4, 4)."""
    t = _dh(q[:, 0], d[0], a[0], _ALPHA[0])
    for i in range(1, 6):
        t = t @ _dh(q[:, i], d[i], a[i], _ALPHA[i])
    return t


def _wrap(q: np.ndarray) -> np.ndarray:
    """Angles into (-π, π]."""
    return np.pi - np.mod(np.pi - q, TWO_PI)


def _nearest_turn(
    q: np.ndarray, near: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> np.ndarray:
    """Each angle's turn θ + 2πk nearest `near`, moved a turn back inside [lower, upper] if
    that one is outside and the next is not."""
    out = q + TWO_PI * np.round((near - q) / TWO_PI)
    out = np.where(out > upper, out - TWO_PI, out)
    return np.where(out < lower, out + TWO_PI, out)


def _transform(pos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = np.asarray(xmat).reshape(3, 3)
    t[:3, 3] = pos
    return t


_CACHE: weakref.WeakKeyDictionary[mujoco.MjModel, URKinematics] = weakref.WeakKeyDictionary()


def of_model(mjm: mujoco.MjModel, joints: Sequence[str]) -> URKinematics:
    """`URKinematics.from_model`, once per model (the served one is read at start)."""
    kin = _CACHE.get(mjm)
    if kin is None:
        kin = _CACHE[mjm] = URKinematics.from_model(mjm, joints)
    return kin
