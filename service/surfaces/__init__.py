"""Surfaces: the ways into a running service besides HTTP (ROS 2 over DDS, rosbridge, Foxglove).

May import: `service.core` (and `service.persistence` for recordings); never the app or api.
"""
