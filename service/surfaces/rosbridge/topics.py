"""rosbridge's topics: topic names ↔ worlds, JointState ↔ commands, bad-message counts.

rosbridge speaks the same ROS graph as the armfleet_ros node: `/joint_commands` and
`/joint_states` are world 0 (the seed's topics), `/world_N/joint_commands` and
`/world_N/joint_states` are world N for the worlds the user exposes, and `/clock` is the
simulated time. A JointState command is checked here before it reaches the control layer so that
a bad one is counted under a stable kind (the control layer validates again and stays the
authority).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.core.sim.types import Snapshot

log = logging.getLogger("armfleet.ros")

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
CLOCK_TOPIC = "/clock"
TF = "tf2_msgs/msg/TFMessage"
STRING = "std_msgs/msg/String"

ROS2 = "ros2"  # the label of commands that came over DDS (metrics, recordings)


class BadMessage(ValueError):
    """A message that changes nothing; `kind` is the counter it goes to, the text says why."""

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(f"{kind}: {detail}")
        self.kind = kind
        self.detail = detail


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

    def namespaces(self) -> dict[str, int]:
        """Namespace → world: the root is world 0 (the seed's), `/world_N` each exposed world."""
        return {"": 0} | {f"/world_{w}": w for w in self.worlds}

    def all_topics(self) -> dict[str, str]:
        """Topic name → ROS 2 type, everything armfleet has on the graph."""
        out = dict.fromkeys([*self.command_topics(), *self.state_topics()], JOINT_STATE_TYPE)
        out[CLOCK_TOPIC] = CLOCK_TYPE
        for ns in self.namespaces():  # the robot topics (frames.py)
            out |= {f"{ns}/tf": TF, f"{ns}/tf_static": TF, f"{ns}/robot_description": STRING}
        return dict(sorted(out.items()))


def sim_seconds(snap: Snapshot, tick_dt: float) -> float:
    """The service's simulated time: control ticks since start × tick length [s].

    One clock for `/clock` and every header stamp (per-world `sim_time` restarts at a world's
    reset, which would make ROS time jump backwards).
    """
    return snap.tick * tick_dt


def stamp(seconds: float) -> tuple[int, int]:
    """Seconds → (sec, nanosec), rounded to the nanosecond, never negative."""
    ns = max(0, round(seconds * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000


def _floats(row: np.ndarray) -> list[float | None]:
    """JSON-safe floats: NaN/Inf become null, as rosbridge sends them."""
    return [v if math.isfinite(v) else None for v in row.tolist()]


def joint_state_dict(
    snap: Snapshot, world: int, joints: Sequence[str], seconds: float
) -> dict[str, Any]:
    """One world's JointState as rosbridge JSON (keys in field order, time as sec/nanosec)."""
    sec, nanosec = stamp(seconds)
    return {
        "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""},
        "name": list(joints),
        "position": _floats(snap.position[world]),
        "velocity": _floats(snap.velocity[world]),
        "effort": _floats(snap.effort[world]),
    }


def clock_dict(seconds: float) -> dict[str, Any]:
    """rosgraph_msgs/Clock as rosbridge JSON."""
    sec, nanosec = stamp(seconds)
    return {"clock": {"sec": sec, "nanosec": nanosec}}


class BadMessageCounter:
    """Counts rejected messages per kind; logs each kind at most once per second (thread-safe).

    A flood of bad messages (a misconfigured node at 1 kHz) would otherwise fill the log; the
    counts stay exact and are shown by `GET /v1/ros`.
    """

    def __init__(self, source: str, interval: float = 1.0) -> None:
        self._source = source
        self._interval = interval
        self._lock = threading.Lock()
        self._counts: dict[str, int] = {}
        self._last_log: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def report(self, kind: str, topic: str, detail: str) -> None:
        now = time.monotonic()
        with self._lock:
            self._counts[kind] = self._counts.get(kind, 0) + 1
            if now - self._last_log.get(kind, -math.inf) < self._interval:
                self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
                return
            self._last_log[kind] = now
            hidden = self._suppressed.pop(kind, 0)
        more = f" ({hidden} more of this kind since the last log line)" if hidden else ""
        log.warning("%s: rejected message on %s: %s: %s%s", self._source, topic, kind, detail, more)

    def counts(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self._counts.values())
