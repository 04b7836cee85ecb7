"""armfleet, the service: many UR10e + Robotiq worlds stepped together, driven from outside.

The folders are the layers, lowest first; a module imports its own layer and those below,
never above (scripts/import_graph.py checks it, tests/test_layout.py runs it):

- core/         types, the `Batch` protocol, the loop, `Control`, hub, wire, schemas
- engines/      the `Batch` implementations (Warp, native MuJoCo, process shards, Ray)
- persistence/  snapshots, MCAP recordings, replay
- surfaces/     the ROS 2 node, rosbridge, Foxglove, recordings: plug-ins on core/surface.py
- api/, app.py, runtime.py, serving.py, settings.py, cli.py   the app: HTTP routes,
  composition, the server, the settings of all (one section each, beside its owner in the
  layers above), the `armfleet` command
"""

from service.core.process.pythonpath import scrub as _scrub_ros_pythonpath

_scrub_ros_pythonpath()  # before anything else is imported: see service/core/process/pythonpath.py
