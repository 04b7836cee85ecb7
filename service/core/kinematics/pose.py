"""UR pose conventions, batched: p[x, y, z, rx, ry, rz] with a rotation vector, and back.

A UR program speaks of a pose as six numbers: a position [m] and a rotation vector [rad] (the
axis scaled by the angle, the angle in 0..π), both in the robot's base frame (URScript `p[...]`,
ur_rtde's `getActualTCPPose`). Everything here takes leading batch dimensions (`...`), so the
poses of all worlds convert in one call; quaternions are w x y z, as MuJoCo writes them.

The rotation vector is read back through a quaternion (Shepperd's method), which stays exact
near an angle of π where the trace formula loses its axis.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "compose",
    "invert",
    "matrix_to_pose",
    "matrix_to_quat",
    "matrix_to_rotvec",
    "pose_to_matrix",
    "quat_to_matrix",
    "rotvec_to_matrix",
    "rotvec_to_quat",
]

_SMALL = 1e-8  # rad: below it, the series of sin(θ)/θ and (1 - cos θ)/θ² are used


def rotvec_to_matrix(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) → rotation matrices (..., 3, 3) (Rodrigues)."""
    r = np.asarray(r, dtype=np.float64)
    theta = np.linalg.norm(r, axis=-1)[..., None, None]
    small = theta < _SMALL
    t = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(t) / t)  # sin θ / θ
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)  # (1 - cos θ) / θ²
    k = _skew(r)
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + a * k + b * (k @ k)


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) → unit quaternions w x y z (..., 4), w >= 0."""
    m = np.asarray(m, dtype=np.float64)
    lead = m.shape[:-2]
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m.reshape(-1, 9).T
    d21, d02, d10 = m21 - m12, m02 - m20, m10 - m01
    s21, s02, s10 = m21 + m12, m02 + m20, m10 + m01
    w4, x4 = 1 + m00 + m11 + m22, 1 + m00 - m11 - m22  # 4w², 4x², 4y², 4z²
    y4, z4 = 1 - m00 + m11 - m22, 1 - m00 - m11 + m22
    # Row k is the quaternion times 4 × its k-th part (Shepperd): the row of the largest of
    # 4w², 4x², 4y², 4z² is the accurate one. Whole rows picked by index, not part by part
    # with np.select: RTDE converts every streaming world's TCP pose at each tick (~3x less
    # CPU for a few worlds).
    rows = np.stack(
        [w4, d21, d02, d10, d21, x4, s10, s02, d02, s10, y4, s21, d10, s02, s21, z4], -1
    ).reshape(-1, 4, 4)
    pick = np.argmax(rows[:, _DIAGONAL, _DIAGONAL], axis=-1)
    q = rows[np.arange(len(rows)), pick]
    q *= np.where(q[:, :1] < 0, -1.0, 1.0) / np.sqrt((q * q).sum(-1, keepdims=True))
    return q.reshape(*lead, 4)


_DIAGONAL = (0, 1, 2, 3)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Quaternions w x y z (..., 4), normalised here → rotation matrices (..., 3, 3)."""
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return np.stack([np.stack(r, -1) for r in rows], -2)


def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Unit quaternions w x y z (..., 4) → rotation vectors (..., 3), angle in 0..π."""
    q = np.where(q[..., :1] < 0, -q, q)
    v = q[..., 1:]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(n, q[..., :1])
    small = n < _SMALL
    scale = np.where(small, 2.0 / np.maximum(q[..., :1], _SMALL), angle / np.where(small, 1.0, n))
    return v * scale


def rotvec_to_quat(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) → unit quaternions w x y z (..., 4)."""
    r = np.asarray(r, dtype=np.float64)
    theta = np.linalg.norm(r, axis=-1, keepdims=True)
    small = theta < _SMALL
    half = np.where(small, 0.5 - theta**2 / 48.0, np.sin(theta / 2) / np.where(small, 1.0, theta))
    return np.concatenate([np.cos(theta / 2), r * half], axis=-1)


def matrix_to_rotvec(m: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) → rotation vectors (..., 3), angle in 0..π."""
    return quat_to_rotvec(matrix_to_quat(m))


def pose_to_matrix(p: np.ndarray) -> np.ndarray:
    """UR poses p[x, y, z, rx, ry, rz] (..., 6) → homogeneous transforms (..., 4, 4)."""
    p = np.asarray(p, dtype=np.float64)
    out = np.zeros((*p.shape[:-1], 4, 4))
    out[..., :3, :3] = rotvec_to_matrix(p[..., 3:])
    out[..., :3, 3] = p[..., :3]
    out[..., 3, 3] = 1.0
    return out


def matrix_to_pose(t: np.ndarray) -> np.ndarray:
    """Homogeneous transforms (..., 4, 4) → UR poses p[x, y, z, rx, ry, rz] (..., 6)."""
    t = np.asarray(t, dtype=np.float64)
    return np.concatenate([t[..., :3, 3], matrix_to_rotvec(t[..., :3, :3])], axis=-1)


def invert(t: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (..., 4, 4)."""
    out = np.zeros_like(t)
    rt = np.swapaxes(t[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -(rt @ t[..., :3, 3:4])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊗ b of UR poses (..., 6): b expressed in a's frame, as URScript's pose_trans(a, b)."""
    return matrix_to_pose(pose_to_matrix(a) @ pose_to_matrix(b))


def _skew(r: np.ndarray) -> np.ndarray:
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    o = np.zeros_like(x)
    return np.stack(
        [np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2
    )


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """u × v over the last axis of (..., 3) arrays: np.cross's result, in a fifth of its time
    on the few rows of a tick's `tcp_state` (np.cross checks and moves axes at each call)."""
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], -1)
