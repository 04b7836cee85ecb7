"""The robot's description for ROS nodes that reach armfleet over HTTP (the armfleet_ros node).

`GET /v1/ros/robot_description` is the URDF (urdf.py) that `/robot_description` carries, and
`GET /v1/ros/frames` the tf tree (tf_frames.py) in a form a node can compose without MuJoCo:
the fixed transforms for `/tf_static`, the bodies (`free`: not part of the robot), and for each
moving frame the two bodies whose world poses (the `WS /v1/ws/view` pose frames, MjModel body
order) give it. Both are computed once per service: the model never changes while it runs.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import mujoco

from service.core.sim.types import RobotSpec
from service.surfaces.ros.tf_frames import FrameTree
from service.surfaces.ros.urdf import ROOT_LINK, free_floating, generate


@cache
def _cached(mjm: mujoco.MjModel, spec: RobotSpec) -> tuple[str, dict[str, Any]]:
    tree = FrameTree(mjm)
    frames = {
        "root": ROOT_LINK,
        "nbody": int(mjm.nbody),
        "static": [
            {"parent": t.parent, "child": t.child, "pos": list(t.pos), "quat": list(t.quat)}
            for t in tree.static
        ],
        "bodies": [  # simulation_interfaces' entities: the robot's links and the free bodies
            {
                "id": b,
                "name": mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_BODY, b) or f"body_{b}",
                "free": free_floating(mjm, b),
            }
            for b in range(1, mjm.nbody)
        ],
        "moving": [
            {"parent": p, "child": c, "parent_body": int(pb), "child_body": int(cb)}
            for p, c, pb, cb in zip(
                tree.moving_parents,
                tree.moving_children,
                tree.parent_bodies,
                tree.child_bodies,
                strict=True,
            )
        ],
    }
    return generate(mjm, spec), frames


def robot_description(mjm: mujoco.MjModel, spec: RobotSpec) -> str:
    """The URDF text (what `/robot_description` holds)."""
    return _cached(mjm, spec)[0]


def frames(mjm: mujoco.MjModel, spec: RobotSpec) -> dict[str, Any]:
    """The tf tree as JSON (see the module docstring)."""
    return _cached(mjm, spec)[1]
