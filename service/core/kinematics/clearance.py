"""How far a joint configuration would put the arm into the table: the robot's safety plane.

A UR stops (protective stop) before its tool or links cross a safety plane or hit what it
stands on. armfleet checks the *commanded* configuration, not the contact the physics makes:
every target a world is given (a trajectory's sample, a servo target, a jog) is run through
the closed-form forward kinematics (ur.py) and the arm's own collision geometry (capsules,
boxes of the served model, the gripper's pads and base included) is measured against the
scene's table top. Why the target and not the contact force:
- it is deterministic: a function of the commands alone, the same on MuJoCo Warp and native
  MuJoCo, in real time and in a replay, not of contact stiffness, solver iterations or the
  tick at which a sensor reading crossed a threshold;
- it stops the arm *before* it presses into the table, as a UR's safety plane does, where a
  force limit would only notice once the servos push against it (a position servo held a few
  millimetres inside the table never reaches its torque limit: the contact takes the force);
- it is cheap: 6 joints' DH frames and a few dozen points per world, vectorised over the
  worlds, only for the worlds whose target changed.
Contact with anything else (a body in the way, the arm carrying too much) is the torque rule
of the UR surface (surfaces/ur/safety.py), which stays beside this one.

Which geometry: every geom below the first arm joint that collides with the table (contype /
conaffinity), as points with a radius (capsule: its two end centres and radius; box: its
corners; sphere: its centre and radius; anything else: its bounding sphere), each fixed to the
DH frame of the arm link that carries it. The gripper's geoms are taken at the gripper's
*actual* opening (closing lowers the 2F-140's pads by 2.4 cm): their points are read at
`FINGER_STEPS` openings across finger_joint's range (the mimic joints set by the model's
equality constraints) and interpolated. Why the actual opening and not the commanded one: the
UR's safety knows the tool as it is mounted, not a gripper's commands, and fingers closing on
an object stop at the object (a finger target of "closed" would put the pads of a gripper
holding a cube just above the table 2 cm into it). The table is the box geom named
`table_top` (a cell without one has no check).
`depth` is how far the deepest point's sphere goes below the top surface, over the top's
footprint [m]: the space under the top counts as table too, so that a target that jumps
through it in one command (a servo target far below) is caught as well as one that moves
into it. The UR surface stops a world whose commanded depth passes `ALLOWED_DEPTH` (a few
millimetres of touching, as a grasp of something flat on the table needs, are allowed).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from service.core.kinematics.pose import invert
from service.core.kinematics.ur import URKinematics

__all__ = ["ALLOWED_DEPTH", "FINGER_STEPS", "TABLE_GEOM", "TableClearance"]

TABLE_GEOM = "table_top"
ALLOWED_DEPTH = 0.005  # m a commanded configuration may reach into the table top
FINGER_STEPS = 15  # gripper openings the points are read at (0.05 rad apart on the 2F-140)


@dataclass(frozen=True)
class TableClearance:
    """The arm's collision points against the table box.

    points: (s, m, 4) homogeneous, each in the DH frame `frame` (m,), at each of s gripper
        openings `openings` (s,) [rad] (s = 1 where there is no gripper joint)
    radius (m,), geom (m,): the sphere around each point, the geom (`geom_names`) it belongs to
    to_table (4, 4): from the base frame to the box's own; half (3,): the box's half sizes
    """

    kin: URKinematics
    points: np.ndarray
    openings: np.ndarray
    frame: np.ndarray
    radius: np.ndarray
    geom: np.ndarray
    geom_names: tuple[str, ...]
    to_table: np.ndarray
    half: np.ndarray

    @classmethod
    def of_model(
        cls,
        mjm: mujoco.MjModel,
        joints: Sequence[str],
        kin: URKinematics,
        finger: str | None = None,
    ) -> TableClearance | None:
        """None when the model has no box geom `table_top` (no table: nothing to check).
        `finger`: the gripper's driving joint (its geoms move with its opening)."""
        table = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_GEOM, TABLE_GEOM)
        if table < 0 or mjm.geom_type[table] != mujoco.mjtGeom.mjGEOM_BOX:
            return None
        ids = [mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joints]
        link_of = {int(mjm.jnt_bodyid[j]): k for k, j in enumerate(ids)}
        geoms = [
            (g, link)
            for g in range(mjm.ngeom)
            if (link := _link(mjm, int(mjm.geom_bodyid[g]), link_of)) is not None
            and (
                (mjm.geom_contype[g] & mjm.geom_conaffinity[table])
                or (mjm.geom_conaffinity[g] & mjm.geom_contype[table])
            )
        ]
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
        table_world = _transform(data.geom_xpos[table], data.geom_xmat[table])
        return cls(
            kin,
            np.stack(per_opening),
            openings,
            np.repeat([link + 1 for _, link in geoms], count),
            np.repeat([_probe(mjm, g)[1] for g, _ in geoms], count),
            np.repeat(np.arange(len(geoms)), count),
            tuple(
                mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom {g}" for g, _ in geoms
            ),
            invert(invert(kin.base_in_world) @ table_world),
            mjm.geom_size[table].copy(),
        )

    def depth(
        self, q: np.ndarray, opening: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """For arm configurations q (n, 6) and gripper openings (n,) [rad] (None: open): how
        deep the deepest collision point goes into the table [m] (n,) (≤ 0: above it by that
        much; -inf: nothing over its footprint), and the index into `geom_names` of the geom
        it belongs to (n,)."""
        points = self._points_at(len(q), opening)  # (n, m, 4)
        # the points in the table's frame: table⁻¹ · DH frame · point
        frames = self.to_table[:3] @ self.kin.frames(q)  # (n, 7, 3, 4)
        local = (frames[:, self.frame] @ points[..., None])[..., 0]  # (n, m, 3)
        over = np.abs(local[..., :2]) - self.half[:2]  # outside the top's footprint by
        beside = np.linalg.norm(np.maximum(over, 0.0), axis=-1)
        # below the top surface, inside the footprint (a sphere: by its radius beside it)
        below = self.half[2] - local[..., 2]
        reach = np.sqrt(np.maximum(self.radius**2 - beside**2, 0.0))
        into = np.where(beside <= self.radius, below + reach, -np.inf)
        deepest = np.argmax(into, axis=1)
        return into[np.arange(len(q)), deepest], self.geom[deepest]

    def _points_at(self, n: int, opening: np.ndarray | None) -> np.ndarray:
        """The points (n, m, 4) at each world's opening, linear between the steps."""
        if opening is None or len(self.openings) == 1:
            return np.broadcast_to(self.points[0], (n, *self.points.shape[1:]))
        lo, hi = self.openings[0], self.openings[-1]
        at = (np.clip(opening, lo, hi) - lo) / (hi - lo) * (len(self.openings) - 1)
        i = np.minimum(at.astype(np.int64), len(self.openings) - 2)
        w = (at - i)[:, None, None]
        return (1 - w) * self.points[i] + w * self.points[i + 1]


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
