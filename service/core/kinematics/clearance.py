"""How far a joint configuration would put the arm into what stands still in its cell: the
robot's safety planes, for every fixed obstacle of the served scene.

A UR stops (protective stop) before its tool or links cross a safety plane or hit what it
stands on. armfleet checks the *commanded* configuration, not the contact the physics makes:
every target a world is given (a trajectory's sample, a servo target, a jog) is run through
the closed-form forward kinematics (ur.py) and the arm's own collision geometry (capsules,
boxes of the served model, the gripper's pads and base included) is measured against every
fixed obstacle of the scene. Why the target and not the contact force:
- it is deterministic: a function of the commands alone, the same on MuJoCo Warp and native
  MuJoCo, in real time and in a replay, not of contact stiffness, solver iterations or the
  tick at which a sensor reading crossed a threshold;
- it stops the arm *before* it presses into an obstacle, as a UR's safety plane does, where a
  force limit would only notice once the servos push against it (a position servo held a few
  millimetres inside the table never reaches its torque limit: the contact takes the force);
- it is cheap: 6 joints' DH frames and a few dozen points per world against a few boxes and
  planes, vectorised over the worlds, only for the worlds whose target changed.
Contact with what moves (the cube, a cell's parts, the arm carrying too much) is the torque
rule (core/commands/torque_watch.py), which stays beside this one.

The obstacles: every geom that stands still (its body welded to the world, not a mocap body)
and collides with at least one of the arm's geoms (contype / conaffinity): in the served cell
the floor, the table top and the pedestal, in a cell of one's own whatever it fixes (a bin's
walls). A plane is the half-space below it; a box is its own box, any other shape the box
that bounds it in its own frame (MuJoCo's `geom_aabb`), and a box counts as solid all the way
down along its own -z: a table top is 5 cm thick, and a target that jumps through it in one
command (a servo target far below) is caught as well as one that moves into it. (A thin wall
crossed sideways in one command is not: the check is of targets, not of the path between.)

Which arm geometry: every geom below the first arm joint that collides with an obstacle, as
points with a radius (capsule: its two end centres and radius; box: its corners; sphere: its
centre and radius; anything else: its bounding sphere), each fixed to the DH frame of the arm
link that carries it. The gripper's geoms are taken at the gripper's *actual* opening (closing
lowers the 2F-140's pads by 2.4 cm): their points are read at `FINGER_STEPS` openings across
finger_joint's range (the mimic joints set by the model's equality constraints) and
interpolated. Why the actual opening and not the commanded one: the UR's safety knows the tool
as it is mounted, not a gripper's commands, and fingers closing on an object stop at the
object (a finger target of "closed" would put the pads of a gripper holding a cube just above
the table 2 cm into it).

`depth` is how far the deepest point's sphere goes into an obstacle [m] (its penetration: the
least distance that would push it out, ≤ 0 when clear by that much). The safety watch
(core/commands/clearance_watch.py) stops a world whose commanded depth passes `ALLOWED_DEPTH`
(a few millimetres of touching, as a grasp of something flat on the table needs, are allowed).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from service.core.kinematics.pose import invert
from service.core.kinematics.ur import URKinematics

__all__ = ["ALLOWED_DEPTH", "FINGER_STEPS", "Clearance"]

ALLOWED_DEPTH = 0.005  # m a commanded configuration may reach into an obstacle
FINGER_STEPS = 15  # gripper openings the points are read at (0.05 rad apart on the 2F-140)
_CAPSULE = mujoco.mjtGeom.mjGEOM_CAPSULE
_PLANE = np.array([np.inf, np.inf, 0.0])  # a plane's "half sizes": the half-space below it


@dataclass(frozen=True)
class Clearance:
    """The arm's collision points against the scene's fixed obstacles.

    points: (s, m, 4) homogeneous, each in the DH frame `frame` (m,), at each of s gripper
        openings `openings` (s,) [rad] (s = 1 where there is no gripper joint)
    radius (m,), geom (m,): the sphere around each point, the geom (`geom_names`) it belongs to
    segments (c, 2): the two points of each capsule (its axis: `depth` measures the whole axis)
    to_obstacle (k, 3, 4): from the base frame to each obstacle's own (its box's centre)
    half (k, 3): each obstacle's half sizes (a plane: inf, inf, 0)
    obstacle_names (k,): the obstacles' geom names
    reach (6,): how far [m] any point (a sphere's centre) may be from each arm joint's axis,
        and finger_reach [m/rad]: how fast the gripper's points move with its opening; so no
        point moves by more than reach · |dq| + finger_reach · |d opening| (a watch that
        measures again only what may have come near, clearance_watch.py)
    """

    kin: URKinematics
    points: np.ndarray
    openings: np.ndarray
    frame: np.ndarray
    radius: np.ndarray
    geom: np.ndarray
    geom_names: tuple[str, ...]
    segments: np.ndarray
    to_obstacle: np.ndarray
    half: np.ndarray
    obstacle_names: tuple[str, ...]
    reach: np.ndarray
    finger_reach: float

    @classmethod
    def of_model(
        cls,
        mjm: mujoco.MjModel,
        joints: Sequence[str],
        kin: URKinematics,
        finger: str | None = None,
    ) -> Clearance | None:
        """None when nothing fixed collides with the arm (nothing to check). `finger`: the
        gripper's driving joint (its geoms move with its opening)."""
        ids = [mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joints]
        link_of = {int(mjm.jnt_bodyid[j]): k for k, j in enumerate(ids)}
        arm = [
            (g, link)
            for g in range(mjm.ngeom)
            if (link := _link(mjm, int(mjm.geom_bodyid[g]), link_of)) is not None
        ]
        fixed = [g for g in range(mjm.ngeom) if _fixed(mjm, g)]
        touch = {g: [o for o in fixed if _collide(mjm, g, o)] for g, _ in arm}
        geoms = [(g, link) for g, link in arm if touch[g]]
        obstacles = [o for o in fixed if any(o in touch[g] for g, _ in geoms)]
        if not geoms:
            return None
        # DH frame k+1 (moving with joint k) in the world frame, at q = 0
        dh_world = kin.base_in_world @ kin.frames(np.zeros((1, 6)))[0]
        openings, hands = _hand_poses(mjm, finger)
        data = mujoco.MjData(mjm)
        per_opening = []
        for hand in hands:
            data.qpos[:] = hand
            data.qpos[mjm.jnt_qposadr[ids]] = 0.0
            mujoco.mj_kinematics(mjm, data)
            pts = []
            for g, link in geoms:
                local, _ = _probe(mjm, g)
                in_frame = invert(dh_world[link + 1]) @ _transform(
                    data.geom_xpos[g], data.geom_xmat[g]
                )
                pts.append((in_frame @ np.c_[local, np.ones(len(local))].T).T)
            per_opening.append(np.concatenate(pts))
        count = [len(_probe(mjm, g)[0]) for g, _ in geoms]
        first = np.cumsum([0, *count[:-1]])
        capsule = [i for i, (g, _) in enumerate(geoms) if mjm.geom_type[g] == _CAPSULE]
        segments = np.array([[first[i], first[i] + 1] for i in capsule], dtype=np.int64)
        to_base = invert(kin.base_in_world)
        boxes = [_box(mjm, data, o) for o in obstacles]
        return cls(
            kin,
            np.stack(per_opening),
            openings,
            np.repeat([link + 1 for _, link in geoms], count),
            np.repeat([_probe(mjm, g)[1] for g, _ in geoms], count),
            np.repeat(np.arange(len(geoms)), count),
            tuple(_name(mjm, g) for g, _ in geoms),
            segments.reshape(-1, 2),
            np.stack([invert(to_base @ t)[:3] for t, _ in boxes]),
            np.stack([h for _, h in boxes]),
            tuple(_name(mjm, o) for o in obstacles),
            *_reach(dh_world, np.stack(per_opening), openings, [link for _, link in geoms], count),
        )

    def depth(
        self, q: np.ndarray, opening: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For arm configurations q (n, 6) and gripper openings (n,) [rad] (None: open): how
        deep the deepest collision point goes into any obstacle [m] (n,) (≤ 0: clear of all
        by that much), the index into `geom_names` of the geom it belongs to (n,), and the
        index into `obstacle_names` of the obstacle (n,)."""
        n, m, k = len(q), len(self.radius), len(self.half)
        points = self._points_at(n, opening)  # (n, m, 4)
        frames = self.kin.frames(q)[:, self.frame, :3, :]  # (n, m, 3, 4): each point's frame
        base = frames[..., 3] + sum(frames[..., j] * points[..., j, None] for j in range(3))
        # each point in each obstacle's frame, one matrix product for all, as x, y, z (n, m, k)
        rot = self.to_obstacle[:, :, :3].transpose(2, 1, 0).reshape(3, 3 * k)
        xyz = (base.reshape(n * m, 3) @ rot).reshape(n, m, 3, k)
        local = [xyz[:, :, i] + self.to_obstacle[:, i, 3] for i in range(3)]
        signed = _signed(*local, *self.half.T)  # (n, m, k)
        into = self.radius[:, None] - signed
        if len(self.segments):
            self._along_capsules(into, local, signed)
        into = into.reshape(n, m * k)
        deepest = np.argmax(into, axis=1)
        return into[np.arange(n), deepest], self.geom[deepest // k], deepest % k

    def _along_capsules(
        self, into: np.ndarray, local: list[np.ndarray], signed: np.ndarray
    ) -> None:
        """A capsule's axis may reach deeper between its two end points (a forearm across a
        box's edge): for every (world, capsule, obstacle) whose ends are not far enough apart
        from the obstacle to rule it out, the least signed distance along the whole axis
        replaces its first end's in `into` (n, m, k). The rule-out is exact: a signed distance
        changes by at most the distance moved, so no point of an axis of length L with ends
        at a and b comes nearer than (a + b - L) / 2."""
        s0, s1 = self.segments[:, 0], self.segments[:, 1]
        step = [v[:, s1] - v[:, s0] for v in local]  # (n, c, k) each
        length = np.sqrt(step[0] ** 2 + step[1] ** 2 + step[2] ** 2)
        bound = 0.5 * (signed[:, s0] + signed[:, s1] - length)
        w, c, o = np.nonzero(bound < self.radius[s0][:, None])  # may touch: measure
        if w.size:
            a = np.stack([v[w, s0[c], o] for v in local], axis=-1)  # (p, 3)
            b = np.stack([v[w, s1[c], o] for v in local], axis=-1)
            least = _least_along(a, b, self.half[o])
            into[w, s0[c], o] = np.maximum(into[w, s0[c], o], self.radius[s0[c]] - least)

    def _points_at(self, n: int, opening: np.ndarray | None) -> np.ndarray:
        """The points (n, m, 4) at each world's opening, linear between the steps."""
        if opening is None or len(self.openings) == 1:
            return np.broadcast_to(self.points[0], (n, *self.points.shape[1:]))
        lo, hi = self.openings[0], self.openings[-1]
        at = (np.clip(opening, lo, hi) - lo) / (hi - lo) * (len(self.openings) - 1)
        i = np.minimum(at.astype(np.int64), len(self.openings) - 2)
        w = (at - i)[:, None, None]
        return (1 - w) * self.points[i] + w * self.points[i + 1]


def _signed(x: np.ndarray, y: np.ndarray, z: np.ndarray, hx: Any, hy: Any, hz: Any) -> np.ndarray:
    """Signed distance of points (x, y, z), each in its obstacle's frame, to the obstacle of
    half sizes (hx, hy, hz) (broadcast): a box solid down along its -z (or a plane's
    half-space), negative inside by the distance to the nearest face. Kept to whole arrays
    per coordinate (no reductions over a last axis of 3: numpy's slowest shape)."""
    ax, ay = np.abs(x), np.abs(y)
    ox, oy, oz = np.maximum(ax - hx, 0.0), np.maximum(ay - hy, 0.0), np.maximum(z - hz, 0.0)
    outside = np.sqrt(ox * ox + oy * oy + oz * oz)
    inside = np.minimum(np.minimum(hx - ax, hy - ay), hz - z)  # ≥ 0 only where outside is 0
    return outside - np.maximum(inside, 0.0)


def _least_along(a: np.ndarray, b: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The least signed distance (p,) along segments a → b (p, 3) to obstacles `half` (p, 3).
    Along a segment it is a convex function of t in [0, 1] whose pieces meet where the segment
    crosses the plane of a face; outside the obstacle each piece is the root of a quadratic.
    So the candidates are the ends, the crossings and each piece's stationary point: exact
    wherever the axis stays outside; an axis that goes in is measured at its ends and
    crossings, where it is already a capsule's radius deep."""
    d = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = np.stack(
            [(half[:, 0] - a[:, 0]) / d[:, 0], (-half[:, 0] - a[:, 0]) / d[:, 0],
             (half[:, 1] - a[:, 1]) / d[:, 1], (-half[:, 1] - a[:, 1]) / d[:, 1],
             (half[:, 2] - a[:, 2]) / d[:, 2]],
            axis=1,
        )  # fmt: skip
    cross = np.where(np.isfinite(cross), np.clip(cross, 0.0, 1.0), 0.0)
    ends = np.zeros((len(a), 2))
    ends[:, 1] = 1.0
    t = np.sort(np.concatenate([ends, cross], axis=1), axis=1)  # (p, 7)
    lo, hi = t[:, :-1], t[:, 1:]
    mid = a[:, None] + (0.5 * (lo + hi))[..., None] * d[:, None]  # (p, 6, 3)
    # the face planes each piece is beyond (x, y: either side; z: above the top only)
    beyond = np.abs(mid) > half[:, None]
    beyond[..., 2] = mid[..., 2] > half[:, None, 2]
    face = np.where(beyond, np.sign(mid) * half[:, None], 0.0)
    face[..., 2] = half[:, None, 2]
    dd = np.where(beyond, d[:, None] ** 2, 0.0).sum(axis=-1)
    da = np.where(beyond, d[:, None] * (a[:, None] - face), 0.0).sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        stationary = np.where(dd > 0.0, np.clip(-da / dd, lo, hi), lo)
    t = np.concatenate([t, stationary], axis=1)  # (p, 13)
    at = [a[:, None, i] + t * d[:, None, i] for i in range(3)]  # (p, 13) each
    return _signed(*at, *(half[:, None, i] for i in range(3))).min(axis=1)


def _reach(
    dh_world: np.ndarray,
    points: np.ndarray,
    openings: np.ndarray,
    links: list[int],
    count: list[int],
) -> tuple[np.ndarray, float]:
    """(reach (6,), finger_reach) of `Clearance`. Joint k turns about the z axis of DH frame k,
    through its origin: a point carried by frame f > k is no farther from that axis than the
    chain of link lengths from frame k to frame f (constant, whatever q) plus its own distance
    from frame f's origin and radius. The gripper's points move linearly between the openings
    they were read at: their fastest step over the step's width bounds them."""
    hops = np.linalg.norm(np.diff(dh_world[:, :3, 3], axis=0), axis=1)  # frame i → i + 1
    frame = np.repeat(np.array(links) + 1, count)
    own = np.linalg.norm(points[..., :3], axis=-1).max(axis=0)  # (m,) farthest opening
    reach = np.array(
        [
            max((hops[k:f].sum() + d for f, d in zip(frame, own, strict=True) if f > k), default=0)
            for k in range(6)
        ]
    )
    if len(openings) < 2:
        return reach, 0.0
    moved = np.linalg.norm(np.diff(points[..., :3], axis=0), axis=-1).max(axis=1)
    return reach, float((moved / np.diff(openings)).max())


def _fixed(mjm: mujoco.MjModel, g: int) -> bool:
    """A geom that stands still: its body welded to the world and not moved as a mocap body."""
    body = int(mjm.geom_bodyid[g])
    return int(mjm.body_weldid[body]) == 0 and int(mjm.body_mocapid[body]) < 0


def _collide(mjm: mujoco.MjModel, a: int, b: int) -> bool:
    return bool(
        (mjm.geom_contype[a] & mjm.geom_conaffinity[b])
        or (mjm.geom_conaffinity[a] & mjm.geom_contype[b])
    )


def _box(mjm: mujoco.MjModel, data: mujoco.MjData, g: int) -> tuple[np.ndarray, np.ndarray]:
    """An obstacle's box in the world: (its centre's frame (4, 4), its half sizes (3,)); a
    plane's are (inf, inf, 0): the half-space below it, `depth` reads the height over it."""
    frame = _transform(data.geom_xpos[g], data.geom_xmat[g])
    if mjm.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE:
        return frame, _PLANE.copy()
    if mjm.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
        return frame, mjm.geom_size[g].copy()
    centre, half = mjm.geom_aabb[g, :3], mjm.geom_aabb[g, 3:]
    shift = np.eye(4)
    shift[:3, 3] = centre
    return frame @ shift, half.copy()


def _name(mjm: mujoco.MjModel, g: int) -> str:
    name = mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_GEOM, g)
    if name:
        return name
    body = mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_BODY, int(mjm.geom_bodyid[g]))
    return f"geom {g} of body {body or mjm.geom_bodyid[g]}"


def _hand_poses(mjm: mujoco.MjModel, finger: str | None) -> tuple[np.ndarray, list[np.ndarray]]:
    """The gripper openings the points are read at [rad], and the model's qpos at rest with
    each: the driving joint `finger` at FINGER_STEPS values across its range, the joints its
    equality constraints tie to it (the 2F-140's five mimic joints, q = c0 + c1 q_finger + ...)
    set to match. No such joint: the rest pose alone."""
    j = -1 if finger is None else mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, finger)
    if j < 0:
        return np.zeros(1), [mjm.qpos0.copy()]
    openings = np.linspace(*mjm.jnt_range[j], FINGER_STEPS)
    poses = []
    for value in openings:
        qpos = mjm.qpos0.copy()
        qpos[mjm.jnt_qposadr[j]] = value
        for e in range(mjm.neq):
            if mjm.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and mjm.eq_obj2id[e] == j:
                c = mjm.eq_data[e, :5]
                qpos[mjm.jnt_qposadr[mjm.eq_obj1id[e]]] = np.polyval(c[::-1], value)
        poses.append(qpos)
    return openings, poses


def _link(mjm: mujoco.MjModel, body: int, link_of: dict[int, int]) -> int | None:
    """The arm joint (0..5) whose link carries `body`: the nearest one on its way to the
    world; None for a body that is not on the arm."""
    while body:
        if body in link_of:
            return link_of[body]
        body = int(mjm.body_parentid[body])
    return None


def _probe(mjm: mujoco.MjModel, g: int) -> tuple[np.ndarray, float]:
    """Points (k, 3) in the geom's frame and the radius of the spheres around them."""
    size, kind = mjm.geom_size[g], mjm.geom_type[g]
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return np.array([[0.0, 0.0, -size[1]], [0.0, 0.0, size[1]]]), float(size[0])
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return np.zeros((1, 3)), float(size[0])
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        return corners * size, 0.0
    return np.zeros((1, 3)), float(mjm.geom_rbound[g])  # the bounding sphere


def _transform(pos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = np.asarray(xmat).reshape(3, 3)
    t[:3, 3] = pos
    return t
