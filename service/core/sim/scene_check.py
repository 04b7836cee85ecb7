"""Is this MJCF a cell armfleet can serve? One clear error before anything is built.

`armfleet serve --scene my_cell.xml` checks the user's scene here (settings validate it) so
that a bad file stops the command with one message naming what is wrong, never a half-started
server: it does not parse; it has no arm (armfleet's UR10e + 2F-140 comes in with
`<include file="ur10e_2f140.xml"/>`); a joint of the arm is missing or renamed; there is no
`home` keyframe; a free body has no name (every free body is an entity, known by its name);
or the cell at `home` already has more contacts than a world holds (`MAX_CONTACTS`, the warp
engine's per-world capacity).
"""

from __future__ import annotations

from pathlib import Path

import mujoco

from service.core.sim.robot import HOME_KEY, LoadedRobot, compile_scene, default_spec, load_robot

# Contacts one world holds on the warp engine (service.engines.warp.NCONMAX, kept equal by a
# test): a cell that starts with more would drop contacts from its first tick.
MAX_CONTACTS = 32

HOME_LINE = (
    '<keyframe><key name="home" qpos="0 -1.57 1.57 -1.57 -1.57 0  0  0 0 0 0 0" '
    'ctrl="0 -1.57 1.57 -1.57 -1.57 0  0"/></keyframe>'
)


class SceneError(ValueError):
    """The scene cannot be served; the message says why and what to do."""


def check_scene(path: Path | str) -> LoadedRobot:
    """The scene compiled and checked, or SceneError naming the one thing wrong."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise SceneError(f"{path}: no such file")
    try:
        mjm = compile_scene(path)
    except ValueError as exc:
        raise SceneError(f"{path} does not parse: {exc}") from None
    joints = default_spec().names
    present = [n for n in joints if mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, n) >= 0]
    if not present:
        raise SceneError(
            f"{path} has no arm: bring armfleet's UR10e + 2F-140 in with <include "
            f'file="ur10e_2f140.xml"/> (joints {joints})'
        )
    missing = [n for n in joints if n not in present]
    if missing:
        raise SceneError(
            f"{path}: the arm's joint {missing[0]!r} is missing (renamed?); the arm's joint, "
            f"actuator and site names stay as armfleet has them: {joints}"
        )
    if mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_KEY, HOME_KEY) < 0:
        raise SceneError(f"{path} has no keyframe 'home'; add the arm's: {HOME_LINE}")
    for j in range(mjm.njnt):
        if mjm.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            body = int(mjm.jnt_bodyid[j])
            if not mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_BODY, body):
                parent = mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_BODY, mjm.body_parentid[body])
                raise SceneError(
                    f"{path}: free body {body} (in {parent or 'world'!r}) has no name; every "
                    f'free body is an entity and needs one: <body name="...">'
                )
    try:
        robot = load_robot(path)
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    data = mujoco.MjData(mjm)
    mujoco.mj_resetDataKeyframe(mjm, data, robot.home_key)
    mujoco.mj_forward(mjm, data)
    if data.ncon > MAX_CONTACTS:
        raise SceneError(
            f"{path}: {data.ncon} contacts at 'home', more than the {MAX_CONTACTS} a world "
            f"holds; space the parts apart or give fixed geometry contype/conaffinity 0"
        )
    return robot
