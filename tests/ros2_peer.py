"""An independent ROS 2 peer for tests/test_ros2.py, run as its own process.

It plays the seed's rclpy node and `ros2 topic echo`: its own DDS participant (Cyclone, with the
loopback configuration from the environment) writes JointState bytes serialised by rosbags'
ROS 2 Humble typestore and decodes whatever armfleet publishes with rosbags too. Nothing from
armfleet's package is imported, so armfleet's message types are judged by rosbags.

cyclonedds needs a type to create a topic; the declarations below (written here, from the .msg
definitions) only name the topics. The bytes go through cyclonedds' raw write/take, untouched.

Protocol: one JSON request per stdin line, one JSON reply per stdout line.
  {"op": "publish", "topic": "/joint_commands", "msg": {"name": [...], "position": [...]}}
  {"op": "publish_raw", "topic": "/joint_commands", "hex": "..."}    bytes as given
  {"op": "latest", "topic": "/joint_states"}   newest sample decoded by rosbags (or null)
  {"op": "matched", "topic": "..."}            wait until armfleet's endpoint on it is matched
"""

import os
import threading
import time
from dataclasses import dataclass, field

import numpy as np
from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import InstanceState, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, bounded_str, float64, int32, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.typesys import Stores, get_typestore

from tests.peer_stdio import serve_lines

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
JOINT_STATE = "sensor_msgs/msg/JointState"
CLOCK = "rosgraph_msgs/msg/Clock"


@dataclass
class Stamp(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Hdr(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Stamp = field(default_factory=Stamp)
    frame_id: str = ""


@dataclass
class JS(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Hdr = field(default_factory=Hdr)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class Clk(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    clock: Stamp = field(default_factory=Stamp)


@dataclass
class G(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: array[uint8, 24] = field(default_factory=lambda: [0] * 24)


@dataclass
class NodeInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: bounded_str[256] = ""  # string<=256 in the .msg
    node_name: bounded_str[256] = ""
    reader_gid_seq: sequence[G] = field(default_factory=list)
    writer_gid_seq: sequence[G] = field(default_factory=list)


@dataclass
class PartInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
    gid: G = field(default_factory=G)
    node_entities_info_seq: sequence[NodeInfo] = field(default_factory=list)


ANY = SampleState.Any | ViewState.Any | InstanceState.Any
# rclpy's create_publisher(..., 10) / create_subscription(..., 10): reliable, volatile, depth 10.
QOS = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000), Policy.History.KeepLast(10))


def rosbags_joint_state(msg: dict) -> bytes:
    """A JointState as the seed's node fills it (name + position), serialised by rosbags."""
    t = TYPESTORE.types
    stamp = msg.get("stamp", [0, 0])
    value = t[JOINT_STATE](
        header=t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=stamp[0], nanosec=stamp[1]), frame_id=""
        ),
        name=list(msg.get("name", [])),
        position=np.array(msg.get("position", []), dtype=np.float64),
        velocity=np.array(msg.get("velocity", []), dtype=np.float64),
        effort=np.array(msg.get("effort", []), dtype=np.float64),
    )
    return bytes(TYPESTORE.serialize_cdr(value, JOINT_STATE))


def decode(raw: bytes, kind: str) -> dict:
    m = TYPESTORE.deserialize_cdr(raw, kind)
    if kind == CLOCK:
        return {"stamp": [m.clock.sec, m.clock.nanosec]}
    return {
        "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
        "frame_id": m.header.frame_id,
        "name": list(m.name),
        "position": [float(v) for v in m.position],
        "velocity": [float(v) for v in m.velocity],
        "effort": [float(v) for v in m.effort],
        "count": 0,
    }


class Peer:
    def __init__(self) -> None:
        self.dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
        self.topics: dict[str, Topic] = {}
        self.writers: dict[str, DataWriter] = {}
        self.readers: dict[str, tuple[DataReader, str]] = {}
        self.latest: dict[str, dict] = {}
        self.counts: dict[str, int] = {}
        self.lock = threading.Lock()
        threading.Thread(target=self._poll, daemon=True).start()

    def _topic(self, name: str, kind: type) -> Topic:
        if name not in self.topics:
            self.topics[name] = Topic(self.dp, "rt" + name, kind)
        return self.topics[name]

    def writer(self, name: str) -> DataWriter:
        if name not in self.writers:
            self.writers[name] = DataWriter(self.dp, self._topic(name, JS), qos=QOS)
        return self.writers[name]

    def reader(self, name: str) -> None:
        with self.lock:
            if name not in self.readers:
                kind = CLOCK if name == "/clock" else JOINT_STATE
                idl = Clk if kind == CLOCK else JS
                self.readers[name] = (DataReader(self.dp, self._topic(name, idl), qos=QOS), kind)

    def _poll(self) -> None:
        while True:
            with self.lock:
                readers = list(self.readers.items())
            for name, (reader, kind) in readers:
                for data, info in ddspy_take(reader._ref, ANY, 64):
                    if info.valid_data:
                        self.latest[name] = decode(bytes(data), kind)
                        self.counts[name] = self.counts.get(name, 0) + 1
            time.sleep(0.005)

    def discovery(self, timeout: float) -> dict:
        """ros_discovery_info as rosbags decodes it, and the endpoints DDS discovery saw."""
        qos = Qos(
            Policy.Reliability.Reliable(max_blocking_time=100_000_000),
            Policy.Durability.TransientLocal,
            Policy.History.KeepLast(1),
        )
        reader = DataReader(self.dp, Topic(self.dp, "ros_discovery_info", PartInfo), qos=qos)
        pubs = BuiltinDataReader(self.dp, BuiltinTopicDcpsPublication)
        subs = BuiltinDataReader(self.dp, BuiltinTopicDcpsSubscription)
        infos: list = []
        deadline = time.monotonic() + timeout
        while not infos and time.monotonic() < deadline:
            for data, info in ddspy_take(reader._ref, ANY, 16):
                if info.valid_data:
                    m = TYPESTORE.deserialize_cdr(
                        bytes(data), "rmw_dds_common/msg/ParticipantEntitiesInfo"
                    )
                    infos.append(m)
            time.sleep(0.05)

        def hexes(gids: list) -> list[str]:
            return [bytes(g.data.tolist()).hex() for g in gids]

        nodes = [
            {
                "participant": bytes(m.gid.data.tolist()).hex(),
                "namespace": n.node_namespace,
                "name": n.node_name,
                "readers": hexes(n.reader_gid_seq),
                "writers": hexes(n.writer_gid_seq),
            }
            for m in infos
            for n in m.node_entities_info_seq
        ]

        def endpoints(builtin: BuiltinDataReader) -> dict[str, list[str]]:
            out: dict[str, list[str]] = {}
            for e in builtin.take(N=256):
                if hasattr(e, "topic_name"):
                    out.setdefault(e.topic_name, []).append(e.key.bytes.hex())
            return out

        return {"nodes": nodes, "writers": endpoints(pubs), "readers": endpoints(subs)}

    def handle(self, req: dict) -> object:
        op, topic = req["op"], req.get("topic", "")
        if op == "publish":
            return ddspy_write(self.writer(topic)._ref, rosbags_joint_state(req["msg"]))
        if op == "publish_raw":
            return ddspy_write(self.writer(topic)._ref, bytes.fromhex(req["hex"]))
        if op == "latest":
            self.reader(topic)
            out = self.latest.get(topic)
            return None if out is None else {**out, "count": self.counts[topic]}
        if op == "discovery":
            return self.discovery(req.get("timeout", 10))
        if op == "matched":
            deadline = time.monotonic() + req.get("timeout", 20)
            while time.monotonic() < deadline:
                if topic.endswith("commands"):
                    n = self.writer(topic).get_publication_matched_status().current_count
                else:
                    self.reader(topic)
                    n = self.readers[topic][0].get_subscription_matched_status().current_count
                if n:
                    return n
                time.sleep(0.05)
            return 0
        raise ValueError(f"unknown op {op!r}")


def main() -> None:
    serve_lines(Peer().handle)


if __name__ == "__main__":
    main()
