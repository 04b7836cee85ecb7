"""What the ROS 2 surfaces are asked for: the armfleet_ros node (on or off, its Python), and
what both it and rosbridge publish (rate, worlds, cameras).

Why a model of its own: the node's supervisor and rosbridge are built from these, plus what
the registry hands every surface (`ServiceFacts`: where the service listens, how many worlds,
access). A world list is checked against the number of worlds by the service's `Settings`,
which holds both. A field's `validation_alias` is its flat name (`ARMFLEET_ROS2_RATE`,
`--ros2-worlds`), kept from the flat model of before.
"""

from __future__ import annotations

from pydantic import BaseModel

from service.core.process.flat_names import BY_BOTH, flat


class Ros2Settings(BaseModel):
    """ROS 2 (`--ros2`, `--ros2-rate`, `--ros2-worlds`, `--ros2-python`, `--ros2-cameras`)."""

    model_config = BY_BOTH

    enabled: bool = flat(
        "ros2", False, "run the armfleet_ros node on the sourced ROS 2 (a supervised child)"
    )
    rate: float = flat(
        "ros2_rate",
        60.0,
        "/joint_states, /clock and /tf rate of the ROS 2 node and rosbridge [Hz]",
        gt=0,
        le=1000,
    )
    worlds: str = flat(
        "ros2_worlds", "", "worlds with /world_N/ topics, e.g. 0-7 (world 0 always has /joint_*)"
    )
    python: str | None = flat(
        "ros2_python",
        None,
        "Python of the ROS 2 installation for --ros2 (default: the sourced one's)",
    )
    cameras: str = flat(
        "ros2_cameras",
        "",
        "cameras on the ROS 2 graph (sensor_msgs/Image + CameraInfo), e.g. wrist",
    )
