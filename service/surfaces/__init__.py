"""Surfaces: the ways into a running service besides the HTTP API, as plug-ins.

Lives here: the registry that builds them from the settings (`registry`), the Foxglove WebSocket
server (`foxglove_live`) and ROS 2 (`ros/`: the armfleet_ros node's supervisor, rosbridge,
topics). Recordings are not a surface: persistence/service.py holds them with snapshots. Each
gets a
`SurfaceContext` (core/surface.py) and nothing else. To add one: a module here and an entry in
`registry.REGISTRY` (see there).

May import: `service.core` and `service.persistence`; never engines, api, the runtime or the
app.
"""
