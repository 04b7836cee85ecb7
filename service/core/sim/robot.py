"""The robot as the service commands it: which MJCF joints are exposed, their limits and home.

Everything here is read from the MJCF so that the model file stays the single source of truth
for names, ranges and the home pose.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from mjcf import ROBOT_XML, SCENE_XML
from service.core.sim.physics import CellPhysics
from service.core.sim.types import NJOINT, JointSpec, RobotSpec

ROBOT_NAME = "UR10e + Robotiq 2F-140"
HOME_KEY = "home"
FLANGE_SITE = "flange"


@dataclass(frozen=True)
class LoadedRobot:
    """A compiled MjModel plus the addresses the engine needs to gather commanded-joint state."""

    mjm: mujoco.MjModel
    spec: RobotSpec
    qpos_adr: np.ndarray  # (7,) qpos address of each commanded joint
    dof_adr: np.ndarray  # (7,) dof address of each commanded joint
    actuator_ids: np.ndarray  # (7,) actuator driving each commanded joint
    flange_site: int
    home_key: int
    # The scene asks MuJoCo to let bodies at rest sleep (<flag sleep="enable"/>): the native
    # engine honours it; `configure` clears the flag on `mjm`, which everything else shares.
    sleep: bool = False
    # The cell's own step options as written (before `configure`): its timestep when it keeps
    # them, and the line `serve` logs about them (physics.CellPhysics).
    own: CellPhysics | None = None


def compile_scene(path: Path | str) -> mujoco.MjModel:
    """Compile a scene. `<include file="ur10e_2f140.xml"/>` finds armfleet's arm wherever the
    scene lives (the file is handed to MuJoCo by name), so a user's cell needs no copy of it."""
    assets = {ROBOT_XML.name: ROBOT_XML.read_bytes()}
    return mujoco.MjModel.from_xml_path(str(path), assets=assets)


def load_robot(path: Path | str = SCENE_XML) -> LoadedRobot:
    """Compile the scene and check it honours the contract the rest of the service relies on."""
    mjm = compile_scene(path)
    # The commanded joints are the actuated ones, in actuator order (the MJCF lists the six arm
    # joints, then finger_joint): the model is the one place that names them.
    names: list[str] = []
    qpos_adr, dof_adr = [], []
    for aid in range(mjm.nu):
        jid = int(mjm.actuator_trnid[aid, 0])
        if mjm.actuator_trntype[aid] != mujoco.mjtTrn.mjTRN_JOINT or jid < 0:
            raise ValueError(f"{path}: actuator {aid} must drive a joint")
        name = mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_JOINT, jid)
        if mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_ACTUATOR, aid) != name:
            raise ValueError(f"{path}: actuator {aid} must be named after its joint {name!r}")
        names.append(name)
        qpos_adr.append(mjm.jnt_qposadr[jid])
        dof_adr.append(mjm.jnt_dofadr[jid])
    if len(names) != NJOINT:
        raise ValueError(f"{path}: {len(names)} actuated joints, the service commands {NJOINT}")
    home_key = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_KEY, HOME_KEY)
    flange = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_SITE, FLANGE_SITE)
    if home_key < 0 or flange < 0:
        raise ValueError(f"{path}: keyframe {HOME_KEY!r} and site {FLANGE_SITE!r} are required")

    vel_limit = _custom_numeric(mjm, "velocity_limit", len(names))
    joints = []
    for i, name in enumerate(names):
        jid = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, name)
        lower, upper = (float(v) for v in mjm.jnt_range[jid])
        joints.append(
            JointSpec(
                name=name,
                lower=lower,
                upper=upper,
                home=float(mjm.key_ctrl[home_key, i]),
                velocity_limit=float(vel_limit[i]),
                effort_limit=float(abs(mjm.actuator_forcerange[i, 1]))
                if mjm.actuator_forcelimited[i]
                else float("inf"),
            )
        )
    return LoadedRobot(
        mjm=mjm,
        spec=RobotSpec(name=ROBOT_NAME, joints=tuple(joints)),
        qpos_adr=np.array(qpos_adr, dtype=np.int32),
        dof_adr=np.array(dof_adr, dtype=np.int32),
        actuator_ids=np.arange(mjm.nu, dtype=np.int32),
        flange_site=flange,
        home_key=home_key,
        sleep=bool(mjm.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP),
        own=CellPhysics.of(mjm),
    )


@functools.cache
def default_spec() -> RobotSpec:
    """The default scene's commanded joints, compiled once (the request schemas list them)."""
    return load_robot().spec


def _custom_numeric(mjm: mujoco.MjModel, name: str, size: int) -> np.ndarray:
    nid = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_NUMERIC, name)
    if nid < 0:
        return np.full(size, np.nan)
    adr, n = mjm.numeric_adr[nid], mjm.numeric_size[nid]
    return np.asarray(mjm.numeric_data[adr : adr + n][:size], dtype=float)
