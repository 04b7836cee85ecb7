"""An independent ROS 2 peer for tests/test_ros2.py, run as its own process.

It plays the seed's rclpy node and `ros2 topic echo`: its own DDS participant (Cyclone, with the
loopback configuration from the environment) writes JointState bytes serialised by rosbags'
ROS 2 Humble typestore and decodes whatever armfleet publishes with rosbags too. Nothing from
armfleet's package is imported, so armfleet's message types are judged by rosbags.

cyclonedds needs a type to create a topic; tests/ros2_types.py builds them from rosbags'
definitions, and they only name the topics: the bytes go through cyclonedds' raw write/take,
untouched.

Protocol: one JSON request per stdin line, one JSON reply per stdout line.
  {"op": "publish", "topic": "/joint_commands", "msg": {"name": [...], "position": [...]}}
  {"op": "publish_raw", "topic": "/joint_commands", "hex": "..."}    bytes as given
  {"op": "latest", "topic": "/joint_states"}   newest sample decoded by rosbags (or null)
  {"op": "matched", "topic": "..."}            wait until armfleet's endpoint on it is matched
"""

import time

from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from tests import ros2_types
from tests.peer_stdio import serve_lines
from tests.ros2_participant import ANY, Participant

TYPESTORE = ros2_types.TYPESTORE
JOINT_STATE = "sensor_msgs/msg/JointState"
CLOCK = "rosgraph_msgs/msg/Clock"
DISCOVERY = "rmw_dds_common/msg/ParticipantEntitiesInfo"
# rclpy's create_publisher(..., 10) / create_subscription(..., 10): reliable, volatile, depth 10.
QOS = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000), Policy.History.KeepLast(10))


def rosbags_joint_state(msg: dict) -> bytes:
    """A JointState as the seed's node fills it (name + position), serialised by rosbags."""
    sec, nanosec = msg.get("stamp", [0, 0])
    header = {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""}
    fields = ("name", "position", "velocity", "effort")
    return ros2_types.serialize(JOINT_STATE, {"header": header} | {k: msg.get(k) for k in fields})


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


class Peer(Participant):
    def __init__(self) -> None:
        self.topics: dict[str, Topic] = {}
        self.writers: dict[str, DataWriter] = {}
        self.latest: dict[str, dict] = {}
        self.counts: dict[str, int] = {}
        super().__init__()

    def _topic(self, name: str, kind: str) -> Topic:
        if name not in self.topics:
            self.topics[name] = Topic(self.dp, "rt" + name, ros2_types.idl_type(kind))
        return self.topics[name]

    def writer(self, name: str) -> DataWriter:
        if name not in self.writers:
            self.writers[name] = DataWriter(self.dp, self._topic(name, JOINT_STATE), qos=QOS)
        return self.writers[name]

    def reader(self, name: str) -> None:
        with self.lock:
            if name not in self.readers:
                kind = CLOCK if name == "/clock" else JOINT_STATE
                self.readers[name] = (DataReader(self.dp, self._topic(name, kind), qos=QOS), kind)

    def received(self, topic: str, ros_type: str, raw: bytes) -> None:
        self.latest[topic] = decode(raw, ros_type)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def discovery(self, timeout: float) -> dict:
        """ros_discovery_info as rosbags decodes it, and the endpoints DDS discovery saw."""
        qos = Qos(
            Policy.Reliability.Reliable(max_blocking_time=100_000_000),
            Policy.Durability.TransientLocal,
            Policy.History.KeepLast(1),
        )
        topic = Topic(self.dp, "ros_discovery_info", ros2_types.idl_type(DISCOVERY))
        reader = DataReader(self.dp, topic, qos=qos)
        pubs = BuiltinDataReader(self.dp, BuiltinTopicDcpsPublication)
        subs = BuiltinDataReader(self.dp, BuiltinTopicDcpsSubscription)
        infos: list = []
        deadline = time.monotonic() + timeout
        while not infos and time.monotonic() < deadline:
            for data, info in ddspy_take(reader._ref, ANY, 16):
                if info.valid_data:
                    infos.append(TYPESTORE.deserialize_cdr(bytes(data), DISCOVERY))
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
