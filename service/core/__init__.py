"""The core: what every engine, surface and route shares, and the one path of a command.

Rooms, lowest first; a room may import the rooms below it, never one above
(`scripts/import_graph.py` ranks them, `tests/test_layout.py` holds the floors):

- `errors` (flat): domain errors, mapped to a status once, in app.py.
- `process/`: the service's process: who stops on SIGINT/SIGTERM, a ROS shell's PYTHONPATH.
- `sim/`: the simulation: domain types, the engine protocol (`batch`), the robot and physics
  read from the MJCF, the scene, the entity table, the loop and its command table, the
  JointState rule and the target arithmetic the loop applies.
- `streams/`: state out to sockets: the hub, frames and their wire forms.
- `commands/`: one class per command kind with its own request body, `Control` (the one door),
  trajectories.
- `cameras/`: which cameras the scene has, pictures on request, their wire form and clocks.
- `access/`: who may read and command: tokens, leases, the middlewares, the redacting filter.
- `contract/`: the HTTP contract's reply models and the OpenAPI fit.
- `settings`, `metrics`, `surface` (flat, on top): what the service is asked to be, what it
  counts, and the plug-in point of surfaces.

May import: the standard library, third-party packages, `mjcf` and the client's public
modules (`clients.models`, `clients.wire`: the wire's own description; `clients.ros_rules`: the
JointState rule every surface and the ROS node apply); never engines,
persistence, surfaces, api or the app.
"""
