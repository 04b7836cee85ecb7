"""DDS quality of service as ROS 2 nodes use it, for every writer and reader of the bridge."""

from __future__ import annotations

from typing import Any

_WRITE_BLOCK_S = 0.01  # a reliable write never holds the publisher thread longer than this


def reliable_qos(depth: int, accept_xcdr2: bool = False) -> Any:
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
