"""The core: what every engine, surface and route shares, and the one path of a command.

Rooms, lowest first; a room may import the rooms below it, never one above
(`scripts/import_graph.py` ranks them, `tests/test_layout.py` holds the floors):

- `errors` (flat): domain errors, mapped to a status once, in app.py.
- `process/`: the service's process: who stops on SIGINT/SIGTERM, a ROS shell's PYTHONPATH,
  and how a settings section declares its flat ARMFLEET_* names (`flat_names`).
- `sim/`: the simulation: domain types, the engine protocol (`batch`), the robot and physics
  read from the MJCF, the scene, the entity table, the loop and its parts (command desk,
  waiters, listeners, pace), the JointState rule and the target arithmetic the loop applies;
  its settings (`sim/settings`).
- `kinematics/`: the arm's kinematics from the model (UR poses, forward, the closed-form
  inverse, the Jacobian, moveL's line) and each world's TCP offset.
- `access/`: who may read and command: tokens, leases, the middlewares, the redacting filter;
  their settings (`access/settings`).
- `streams/`: state out to sockets: the hub, frame formats, frames and their wire forms.
- `commands/`: one class per command kind with its own request body, `Control` (the one door),
  trajectories.
- `cameras/`: which cameras the scene has, pictures on request, their wire form and clocks;
  their settings (`cameras/settings`).
- `contract/`: the HTTP contract's reply models and the OpenAPI fit.
- `metrics`, `surface` (flat, on top): what the service counts, and the plug-in point of
  surfaces (what a surface is built from and started with). The service's settings as a whole
  are service/settings.py: their sections live beside their owners, some above the core.

May import: the standard library, third-party packages, `mjcf` and the client's public
modules (`clients.models`, `clients.wire`: the wire's own description; `clients.ros_rules`: the
JointState rule every surface and the ROS node apply); never engines,
persistence, surfaces, api or the app.
"""
