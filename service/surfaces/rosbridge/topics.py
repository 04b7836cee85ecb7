"""rosbridge's topics: topic names ↔ worlds, and the messages it sends (states, clock, safety).

rosbridge speaks the same ROS graph as the armfleet_ros node: `/joint_commands` and
`/joint_states` are world 0 (the seed's topics), `/world_N/joint_commands` and
`/world_N/joint_states` are world N for the worlds the user exposes, and `/clock` is the
simulated time. Each world's safety mode is on `io_and_status_controller/safety_mode` of its
namespace (std_msgs/UInt8, UR's number; sent when it changes, and at once to a new subscriber,
as a latched topic: the rulebook's names and type, as the node's). A JointState command is
judged by the rule of every surface (the ROS rulebook, clients/ros_rules.py, through the
control layer), and a refusal is counted under its kind by the rulebook's `RefusalCounter`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from clients import ros_rules
from service.core.sim.types import Snapshot

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
CLOCK_TOPIC = "/clock"
TF = "tf2_msgs/msg/TFMessage"
SAFETY_MODE_TYPE = ros_rules.SAFETY_MODE_TYPE
STRING = "std_msgs/msg/String"

ROS2 = "ros2"  # the label of commands that came over DDS (metrics, recordings)


@dataclass(frozen=True)
class TopicMap:
    """Which worlds are on the ROS graph and under which names.

    worlds: the worlds with `/world_N/...` topics (world 0 also has the seed's plain names)
    """

    worlds: tuple[int, ...]

    def command_topics(self) -> dict[str, int]:
        """Topic name → world, for every topic a command may arrive on."""
        out = {"/joint_commands": 0}
        out.update({f"/world_{w}/joint_commands": w for w in self.worlds})
        return out

    def state_topics(self) -> dict[str, int]:
        """Topic name → world, for every JointState topic armfleet publishes."""
        out = {"/joint_states": 0}
        out.update({f"/world_{w}/joint_states": w for w in self.worlds})
        return out

    def safety_topics(self) -> dict[str, int]:
        """Topic name → world, for every safety mode topic armfleet publishes."""
        return {f"{ns}/{ros_rules.SAFETY_MODE_TOPIC}": w for ns, w in self.namespaces().items()}

    def namespaces(self) -> dict[str, int]:
        """Namespace → world: the root is world 0 (the seed's), `/world_N` each exposed world."""
        return {"": 0} | {f"/world_{w}": w for w in self.worlds}

    def all_topics(self) -> dict[str, str]:
        """Topic name → ROS 2 type, everything armfleet has on the graph."""
        out = dict.fromkeys([*self.command_topics(), *self.state_topics()], JOINT_STATE_TYPE)
        out[CLOCK_TOPIC] = CLOCK_TYPE
        out |= dict.fromkeys(self.safety_topics(), SAFETY_MODE_TYPE)
        for ns in self.namespaces():  # the robot topics (frames.py)
            out |= {f"{ns}/tf": TF, f"{ns}/tf_static": TF, f"{ns}/robot_description": STRING}
        return dict(sorted(out.items()))


def sim_seconds(snap: Snapshot, tick_dt: float) -> float:
    """The service's simulated time: control ticks since start × tick length [s].

    One clock for `/clock` and every header stamp (per-world `sim_time` restarts at a world's
    reset, which would make ROS time jump backwards).
    """
    return snap.tick * tick_dt


def _floats(row: np.ndarray) -> list[float | None]:
    """JSON-safe floats: NaN/Inf become null, as rosbridge sends them."""
    return [v if math.isfinite(v) else None for v in row.tolist()]


def joint_state_dict(
    snap: Snapshot, world: int, joints: Sequence[str], seconds: float
) -> dict[str, Any]:
    """One world's JointState as rosbridge JSON (keys in field order, time as sec/nanosec)."""
    sec, nanosec = ros_rules.stamp(seconds)
    return {
        "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""},
        "name": list(joints),
        "position": _floats(snap.position[world]),
        "velocity": _floats(snap.velocity[world]),
        "effort": _floats(snap.effort[world]),
    }


def safety_mode_dict(snap: Snapshot, world: int) -> dict[str, Any]:
    """std_msgs/UInt8 with the world's safety mode as UR numbers it (1 NORMAL, 3
    PROTECTIVE_STOP), as rosbridge JSON."""
    mode = 1 if snap.safety is None else int(snap.safety[world])
    return {"data": mode}


def clock_dict(seconds: float) -> dict[str, Any]:
    """rosgraph_msgs/Clock as rosbridge JSON."""
    sec, nanosec = ros_rules.stamp(seconds)
    return {"clock": {"sec": sec, "nanosec": nanosec}}
