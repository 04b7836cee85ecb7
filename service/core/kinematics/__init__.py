"""Kinematics of the served arm, batched over worlds: UR poses, forward and inverse.

- `pose`: UR pose conventions, p[x, y, z, rx, ry, rz] (rotation vector) ↔ transforms and
  quaternions, with leading batch dimensions.
- `ur`: `URKinematics` read from the model (flange/TCP poses in the robot's base frame, the
  Jacobian, the closed-form inverse nearest a given q); `of_model` caches one per model.
- `line`: a straight TCP line (moveL) as joint samples with velocities, for the trajectories.

May import: the standard library, numpy, mujoco and `service.core.errors`; nothing else of the
service (the loop, commands and surfaces call in here).
"""
