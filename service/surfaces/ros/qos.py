"""The DDS QoS profiles ROS 2 nodes use, in the terms of the cyclonedds Python API."""

from __future__ import annotations

from typing import Any

_WRITE_BLOCK_S = 0.01  # a reliable write never holds the publisher thread longer than this


def rclpy_default(depth: int, accept_xcdr2: bool = False) -> Any:
    """rclpy's default QoS (RELIABLE, VOLATILE, KEEP_LAST depth) in plain CDR (XCDR1).

    XCDR1 is what ROS 2 Humble writes and reads (XCDR2 lays the string sequence out
    differently), so writers offer only that; readers also take XCDR2 from newer peers.
    """
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.util import duration

    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(seconds=_WRITE_BLOCK_S)),
        Policy.Durability.Volatile,
        Policy.History.KeepLast(depth),
        Policy.DataRepresentation(
            use_cdrv0_representation=True, use_xcdrv2_representation=accept_xcdr2
        ),
    )


def latched() -> Any:
    """Reliable, transient-local, depth 1: what robot_state_publisher and tf2's static
    broadcaster offer, so a node that starts later still gets the description and frames."""
    from cyclonedds.qos import Policy, Qos

    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=0),
        Policy.Durability.TransientLocal,
        Policy.History.KeepLast(1),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )
