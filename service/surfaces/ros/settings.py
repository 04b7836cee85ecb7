"""What the ROS 2 surfaces are asked for: the armfleet_ros node (on or off, its Python), and
what both it and rosbridge publish (rate, worlds, cameras).

Why a model of its own: the node's supervisor and rosbridge are built from these, plus what
the registry hands every surface (`ServiceFacts`: where the service listens, how many worlds,
access). A world list is checked against the number of worlds by the service's `Settings`,
which holds both. A field's `validation_alias` is its flat name (`ARMFLEET_ROS2_RATE`,
`--ros2-worlds`), kept from the flat model of before.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class Ros2Settings(BaseModel):
    """ROS 2 (`--ros2`, `--ros2-rate`, `--ros2-worlds`, `--ros2-python`, `--ros2-cameras`)."""

    model_config = ConfigDict(extra="forbid", validate_by_name=True, validate_by_alias=True)

    enabled: bool = Field(
        False,
        validation_alias="ros2",
        description="run the armfleet_ros node on the sourced ROS 2 (a supervised child)",
    )
    rate: float = Field(
        60.0,
        gt=0,
        le=1000,
        validation_alias="ros2_rate",
        description="/joint_states, /clock and /tf rate of the ROS 2 node and rosbridge [Hz]",
    )
    worlds: str = Field(
        "",
        validation_alias="ros2_worlds",
        description="worlds with /world_N/ topics, e.g. 0-7 (world 0 always has /joint_*)",
    )
    python: str | None = Field(
        None,
        validation_alias="ros2_python",
        description="Python of the ROS 2 installation for --ros2 (default: the sourced one's)",
    )
    cameras: str = Field(
        "",
        validation_alias="ros2_cameras",
        description="cameras on the ROS 2 graph (sensor_msgs/Image + CameraInfo), e.g. wrist",
    )
