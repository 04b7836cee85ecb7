"""The robot's frames as tf2 sees them: fixed transforms for `/tf_static`, moving ones for `/tf`.

The frame tree is the URDF's (urdf.py): one frame per link, named like it. Fixed
joints (bodies without joints, sites) never change and go to `/tf_static` once; a joint's
transform is read from the snapshot's body poses (MuJoCo's own forward kinematics, mimic joints
included), parent frame to child frame, for every world with one vectorised step.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from clients import quat as quaternion
from service.surfaces.ros.urdf import ROOT_LINK, robot_links


@dataclass(frozen=True)
class Transform:
    """child's pose in parent's frame; quat is w x y z."""

    parent: str
    child: str
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float]


class FrameTree:
    """Which frames move and how to read them from body poses."""

    def __init__(self, mjm: mujoco.MjModel) -> None:
        links = robot_links(mjm)
        body_of = {ROOT_LINK: 0} | {link.name: link.body for link in links if link.site < 0}
        self.static = [
            Transform(link.parent, link.name, link.pos, link.quat)
            for link in links
            if link.joint < 0
        ]
        moving = [link for link in links if link.joint >= 0]
        self.moving_parents = [link.parent for link in moving]
        self.moving_children = [link.name for link in moving]
        self._parent_body = np.array([body_of[link.parent] for link in moving], dtype=np.int64)
        self._child_body = np.array([link.body for link in moving], dtype=np.int64)

    @property
    def parent_bodies(self) -> list[int]:
        """The body whose pose is each moving frame's parent frame (MjModel order)."""
        return self._parent_body.tolist()

    @property
    def child_bodies(self) -> list[int]:
        """The body whose pose is each moving frame."""
        return self._child_body.tolist()

    @property
    def frames(self) -> list[str]:
        """Every frame of the tree, root first."""
        return [ROOT_LINK] + [t.child for t in self.static] + self.moving_children

    def moving(self, body_pos: np.ndarray, body_quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Moving frames in their parents' frames from world-frame body poses.

        body_pos (..., nbody, 3), body_quat (..., nbody, 4 as w x y z) → pos (..., k, 3),
        quat (..., k, 4 as w x y z), in the order of `moving_children`.
        """
        pos = np.asarray(body_pos, dtype=np.float64)
        quat = np.asarray(body_quat, dtype=np.float64)
        pp, pq = pos[..., self._parent_body, :], quat[..., self._parent_body, :]
        cp, cq = pos[..., self._child_body, :], quat[..., self._child_body, :]
        inv = quaternion.conj(pq)
        rel_q = quaternion.mul(inv, cq)
        rel_q /= np.linalg.norm(rel_q, axis=-1, keepdims=True)  # float32 poses: renormalise
        return quaternion.rotate(inv, cp - pp), rel_q
