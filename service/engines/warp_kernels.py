"""The warp engine's per-tick gather kernels, captured at the end of every tick (engines.warp).

`gather_state` reads the commanded joints, the flange pose and the fault checks into one compact
(nworld, 28) array; `gather_bodies` every body's pose, for viewers. Kept apart from the engine's
bookkeeping so that each module stays one job.
"""

from __future__ import annotations

import warp as wp

# A joint spinning faster than this [rad/s or m/s] has blown up even if it is still finite.
_DIVERGED_QVEL = wp.constant(1.0e4)


@wp.kernel(enable_backward=False)
def gather_state(
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    qfrc_actuator: wp.array2d(dtype=float),
    site_xpos: wp.array2d(dtype=wp.vec3),
    site_xmat: wp.array2d(dtype=wp.mat33),
    overflow: wp.array(dtype=int),
    qpos_adr: wp.array(dtype=int),
    dof_adr: wp.array(dtype=int),
    flange: int,
    overflow_mask: int,
    state_out: wp.array2d(dtype=float),
    fault_out: wp.array(dtype=int),
    nfault_out: wp.array(dtype=int),
):
    w = wp.tid()
    bad = (overflow[w] & overflow_mask) != 0
    for i in range(qpos.shape[1]):
        if not wp.isfinite(qpos[w, i]):
            bad = True
    for i in range(qvel.shape[1]):
        v = qvel[w, i]
        if not wp.isfinite(v) or wp.abs(v) > _DIVERGED_QVEL:
            bad = True
    for j in range(7):
        state_out[w, j] = qpos[w, qpos_adr[j]]
        state_out[w, 7 + j] = qvel[w, dof_adr[j]]
        state_out[w, 14 + j] = qfrc_actuator[w, dof_adr[j]]
    p = site_xpos[w, flange]
    q = wp.quat_from_matrix(site_xmat[w, flange])  # warp quats are x, y, z, w
    state_out[w, 21] = p[0]
    state_out[w, 22] = p[1]
    state_out[w, 23] = p[2]
    state_out[w, 24] = q[3]
    state_out[w, 25] = q[0]
    state_out[w, 26] = q[1]
    state_out[w, 27] = q[2]
    if bad:
        fault_out[w] = 1
        wp.atomic_add(nfault_out, 0, 1)
    else:
        fault_out[w] = 0


@wp.kernel(enable_backward=False)
def gather_bodies(
    xpos: wp.array2d(dtype=wp.vec3),
    xquat: wp.array2d(dtype=wp.quat),
    out: wp.array3d(dtype=float),
):
    # Every body's world pose, for viewers: position, then the quaternion as MuJoCo stores it
    # (w, x, y, z; mujoco_warp keeps MuJoCo's component order in its quat arrays).
    w, b = wp.tid()
    p = xpos[w, b]
    q = xquat[w, b]
    for i in range(3):
        out[w, b, i] = p[i]
    for i in range(4):
        out[w, b, 3 + i] = q[i]
