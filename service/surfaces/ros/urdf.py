"""A URDF of the robot, generated from the compiled MuJoCo model (what `/robot_description` holds).

ROS tools (RViz, MoveIt, robot_state_publisher) learn a robot's links, joints and shapes from a
URDF; writing one by hand would drift from the MJCF. So it is derived from the compiled
`MjModel`, the single source of truth:

- links: every body that is not the world and not part of a free-floating subtree (the cube),
  plus one fixed link per site on them (`flange`, `pinch`: tool frames RViz can show), and the
  root link `world` (MuJoCo's world frame, the frame of `/tf`);
- joints: a body's hinge joint becomes `revolute` (`continuous` when unlimited) and a slide
  joint `prismatic`, with the axis, the range, the actuator's force limit and the model's
  `velocity_limit`; a body without joints hangs on a `fixed` joint; joint equality constraints
  that make one joint a linear function of another become `<mimic>` (the gripper linkage);
- visuals: the primitive geoms a viewer shows (box, sphere, cylinder; a capsule as a cylinder
  and two spheres), with their colours; inertials from the body masses and inertias.

Each link's frame is the MuJoCo body frame, so the frames in `/tf` (tf_frames.py)
are MuJoCo's body poses, and forward kinematics over this URDF gives them back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np

from service.core.sim.scene import VISIBLE_GROUPS
from service.core.sim.types import RobotSpec

ROOT_LINK = "world"

_JOINT_TYPES = {
    int(mujoco.mjtJoint.mjJNT_HINGE): "revolute",
    int(mujoco.mjtJoint.mjJNT_SLIDE): "prismatic",
}


@dataclass(frozen=True)
class Link:
    """One URDF link and the joint that attaches it to its parent.

    body: the MuJoCo body whose frame this link is (a site's link: the site's body)
    joint: MuJoCo joint id moving it, or -1 for a fixed joint
    pos, quat: the link frame in the parent link's frame at joint value 0 (quat w x y z)
    """

    name: str
    parent: str
    body: int
    joint: int
    joint_name: str
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    site: int = -1
    alias: bool = False  # a UR frame name (`base_link`, `tool0`): a frame only, no shapes


def _name(mjm: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(mjm, obj, i) or f"{obj.name.removeprefix('mjOBJ_').lower()}_{i}"


def free_floating(mjm: mujoco.MjModel, body: int) -> bool:
    """True if the body or an ancestor has a free joint (it is scenery, not the robot)."""
    while body > 0:
        start, count = mjm.body_jntadr[body], mjm.body_jntnum[body]
        if any(mjm.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE for j in range(start, start + count)):
            return True
        body = int(mjm.body_parentid[body])
    return False


def robot_links(mjm: mujoco.MjModel) -> list[Link]:
    """The URDF's links in tree order (parents first); raises ValueError for what URDF can't say.

    URDF joints turn about an axis through the child frame's origin, and a link has one joint:
    a body with two joints, or a joint placed away from its body's origin, has no URDF form.
    """
    links: list[Link] = []
    bodies = [b for b in range(1, mjm.nbody) if not free_floating(mjm, b)]
    for b in bodies:
        name = _name(mjm, mujoco.mjtObj.mjOBJ_BODY, b)
        parent_id = int(mjm.body_parentid[b])
        parent = ROOT_LINK if parent_id == 0 else _name(mjm, mujoco.mjtObj.mjOBJ_BODY, parent_id)
        count = int(mjm.body_jntnum[b])
        if count > 1:
            raise ValueError(f"body {name!r} has {count} joints; a URDF link has one")
        joint = int(mjm.body_jntadr[b]) if count else -1
        if joint >= 0:
            if int(mjm.jnt_type[joint]) not in _JOINT_TYPES:
                raise ValueError(f"joint of body {name!r}: only hinge and slide joints map")
            if np.any(np.abs(mjm.jnt_pos[joint]) > 1e-12):
                raise ValueError(f"joint of body {name!r} is off the body origin")
        joint_name = (
            _name(mjm, mujoco.mjtObj.mjOBJ_JOINT, joint) if joint >= 0 else f"{parent}_to_{name}"
        )
        links.append(
            Link(
                name,
                parent,
                b,
                joint,
                joint_name,
                _tuple(mjm.body_pos[b]),
                _tuple(mjm.body_quat[b]),
            )
        )
    owned = set(bodies)
    for s in range(mjm.nsite):
        body = int(mjm.site_bodyid[s])
        if body in owned:
            parent = _name(mjm, mujoco.mjtObj.mjOBJ_BODY, body)
            name = _name(mjm, mujoco.mjtObj.mjOBJ_SITE, s)
            pos, quat = _tuple(mjm.site_pos[s]), _tuple(mjm.site_quat[s])
            links.append(Link(name, parent, body, -1, f"{parent}_to_{name}", pos, quat, site=s))
    links += _ur_frames(links)
    names = [ROOT_LINK] + [link.name for link in links]
    if len(set(names)) != len(names):
        raise ValueError("body and site names must be unique to name URDF links")
    return links


# Frames ur_description names that the model has no body or site for: (name, parent, quat w x y z).
# The model's `base` body is ur_description's `base` (base_link turned half a turn about z), and
# its `flange` site sits on the flange face with wrist_3_link's axes (z out of the tool), which
# are tool0's; so a chain `base_link` -> `tool0` resolves as on a real UR.
_UR_FRAMES = (
    ("base_link", "base", (0.0, 0.0, 0.0, 1.0)),
    ("tool0", "flange", (1.0, 0.0, 0.0, 0.0)),
)


def _ur_frames(links: list[Link]) -> list[Link]:
    """The UR frame names missing from the model, fixed to the frames they are defined from."""
    have = {link.name: link for link in links}
    out = []
    for name, parent, quat in _UR_FRAMES:
        if name not in have and parent in have:
            body = have[parent].body
            out.append(
                Link(
                    name, parent, body, -1, f"{parent}_to_{name}", (0.0, 0.0, 0.0), quat, alias=True
                )
            )
    return out


def _tuple(values: np.ndarray) -> tuple:
    return tuple(float(v) for v in values)


def _num(value: float) -> str:
    """Shortest round-trip text of a float, without negative zeros."""
    text = repr(float(value) + 0.0)
    return "0" if text in ("0.0", "-0.0") else text


def _nums(values: object) -> str:
    return " ".join(_num(v) for v in values)  # type: ignore[attr-defined]


def quat_to_rpy(quat: tuple[float, ...] | np.ndarray) -> tuple[float, float, float]:
    """Quaternion (w x y z) → URDF roll, pitch, yaw: R = Rz(yaw) · Ry(pitch) · Rx(roll)."""
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    r = mat.reshape(3, 3)
    if abs(r[2, 0]) < 1 - 1e-12:
        return (
            math.atan2(r[2, 1], r[2, 2]),
            math.asin(-r[2, 0]),
            math.atan2(r[1, 0], r[0, 0]),
        )
    pitch = math.copysign(math.pi / 2, -r[2, 0])  # gimbal lock: roll folds into yaw
    return 0.0, pitch, math.atan2(-r[0, 1], r[1, 1])


def _origin(pos: object, quat: object) -> str:
    return f'<origin xyz="{_nums(pos)}" rpy="{_nums(quat_to_rpy(quat))}"/>'  # type: ignore[arg-type]


def _shapes(mjm: mujoco.MjModel, g: int) -> list[tuple[str, np.ndarray]]:
    """The URDF shape(s) of one geom, each with its position in the geom frame."""
    size = mjm.geom_size[g]
    kind = int(mjm.geom_type[g])
    at = np.zeros(3)
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return [(f'<box size="{_nums(2 * size)}"/>', at)]
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return [(f'<sphere radius="{_num(size[0])}"/>', at)]
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return [(f'<cylinder radius="{_num(size[0])}" length="{_num(2 * size[1])}"/>', at)]
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        ball = f'<sphere radius="{_num(size[0])}"/>'
        ends = [np.array([0.0, 0.0, s * size[1]]) for s in (-1, 1)]
        rod = f'<cylinder radius="{_num(size[0])}" length="{_num(2 * size[1])}"/>'
        return [(rod, at), (ball, ends[0]), (ball, ends[1])]
    return []  # planes, meshes, height fields, ellipsoids: no primitive of their own in URDF


def _visuals(mjm: mujoco.MjModel, link: Link, materials: dict[tuple, str]) -> list[str]:
    out = []
    for g in range(mjm.ngeom):
        if int(mjm.geom_bodyid[g]) != link.body or link.site >= 0 or link.alias:
            continue
        if int(mjm.geom_group[g]) not in VISIBLE_GROUPS or mjm.geom_rgba[g, 3] == 0:
            continue
        mat = int(mjm.geom_matid[g])
        color = mjm.mat_rgba[mat] if mat >= 0 else mjm.geom_rgba[g]
        rgba = tuple(round(float(v), 4) for v in color)
        material = materials.setdefault(rgba, f"color_{len(materials)}")
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, mjm.geom_quat[g])
        for shape, offset in _shapes(mjm, g):
            pos = mjm.geom_pos[g] + rot.reshape(3, 3) @ offset
            out.append(
                f"    <visual>{_origin(pos, mjm.geom_quat[g])}<geometry>{shape}</geometry>"
                f'<material name="{material}"/></visual>'
            )
    return out


def _inertial(mjm: mujoco.MjModel, link: Link) -> str:
    mass = float(mjm.body_mass[link.body])
    if link.site >= 0 or link.alias or mass <= 0:
        return ""
    ixx, iyy, izz = (_num(v) for v in mjm.body_inertia[link.body])
    return (
        f"    <inertial>{_origin(mjm.body_ipos[link.body], mjm.body_iquat[link.body])}"
        f'<mass value="{_num(mass)}"/><inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" '
        f'iyz="0" izz="{izz}"/></inertial>'
    )


def _mimics(mjm: mujoco.MjModel) -> dict[int, tuple[int, float, float]]:
    """joint → (leader joint, multiplier, offset) from linear joint equality constraints."""
    out = {}
    for e in range(mjm.neq):
        if mjm.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or not mjm.eq_active0[e]:
            continue
        follower, leader = int(mjm.eq_obj1id[e]), int(mjm.eq_obj2id[e])
        coef = mjm.eq_data[e, :5]
        if leader >= 0 and not np.any(coef[2:]):
            out[follower] = (leader, float(coef[1]), float(coef[0]))
    return out


def _joint(mjm: mujoco.MjModel, link: Link, spec: RobotSpec, mimics: dict) -> str:
    head = f"  <joint name={quoteattr(link.joint_name)} type="
    body = (
        f"    <parent link={quoteattr(link.parent)}/><child link={quoteattr(link.name)}/>"
        f"{_origin(link.pos, link.quat)}"
    )
    j = link.joint
    if j < 0:
        return f'{head}"fixed">\n{body}\n  </joint>'
    kind = _JOINT_TYPES[int(mjm.jnt_type[j])]
    limited = bool(mjm.jnt_limited[j])
    if kind == "revolute" and not limited:
        kind = "continuous"
    body += f'\n    <axis xyz="{_nums(mjm.jnt_axis[j])}"/>'
    commanded = {js.name: js for js in spec.joints}.get(link.joint_name)
    effort = float(abs(mjm.jnt_actfrcrange[j, 1])) if mjm.jnt_actfrclimited[j] else 0.0
    velocity = 0.0
    if commanded is not None:
        velocity = commanded.velocity_limit if math.isfinite(commanded.velocity_limit) else 0.0
        if math.isfinite(commanded.effort_limit):
            effort = commanded.effort_limit
    limit = f'effort="{_num(effort)}" velocity="{_num(velocity)}"'
    if limited:
        lower, upper = mjm.jnt_range[j]
        limit = f'lower="{_num(lower)}" upper="{_num(upper)}" ' + limit
    body += f"\n    <limit {limit}/>"
    if j in mimics:
        leader, multiplier, offset = mimics[j]
        name = quoteattr(_name(mjm, mujoco.mjtObj.mjOBJ_JOINT, leader))
        factor = f'multiplier="{_num(multiplier)}" offset="{_num(offset)}"'
        body += f"\n    <mimic joint={name} {factor}/>"
    return f'{head}"{kind}">\n{body}\n  </joint>'


def generate(mjm: mujoco.MjModel, spec: RobotSpec, name: str = "ur10e_2f140") -> str:
    """The URDF text of the model's robot (see the module docstring for what maps to what)."""
    links = robot_links(mjm)
    mimics = _mimics(mjm)
    materials: dict[tuple, str] = {}
    parts = [f"  <link name={quoteattr(ROOT_LINK)}/>"]
    for link in links:
        inner = [p for p in [_inertial(mjm, link), *_visuals(mjm, link, materials)] if p]
        if inner:
            inside = "\n".join(inner)
            parts.append(f"  <link name={quoteattr(link.name)}>\n{inside}\n  </link>")
        else:
            parts.append(f"  <link name={quoteattr(link.name)}/>")
        parts.append(_joint(mjm, link, spec, mimics))
    colors = [
        f'  <material name="{m}"><color rgba="{_nums(rgba)}"/></material>'
        for rgba, m in materials.items()
    ]
    return (
        '<?xml version="1.0"?>\n'
        "<!-- Generated by armfleet from the compiled MuJoCo model; link frame = body frame -->\n"
        f"<robot name={quoteattr(name)}>\n" + "\n".join(colors + parts) + "\n</robot>\n"
    )
