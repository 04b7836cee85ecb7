"""Surfaces: the ways into a running service besides the HTTP API, as plug-ins.

Lives here: the registry that builds them, each from its own settings model (`registry`),
Foxglove (`foxglove/`: the live WebSocket server and the camera recording) and ROS 2 (`ros/`:
the armfleet_ros node's supervisor, rosbridge, topics). The state recording is not a surface:
persistence/service.py holds it with snapshots. Each is built from its own settings and the
`ServiceFacts`, and started with a `SurfaceContext` (both core/surface.py), nothing else. To
add one: a module here, its settings model beside it, and an entry in `registry.REGISTRY`
(see there).

May import: `service.core` and `service.persistence`; never engines, api, the runtime or the
app.
"""
