"""An independent ROS 2 peer for the UR-driver interfaces (tests/test_ros_ur.py), own process.

It plays what a ROS 2 node with rmw_cyclonedds_cpp does: its own DDS participant subscribes and
publishes any type rosbags knows (bytes serialised and decoded by rosbags, see
tests/ros2_types.py), and calls services the rmw way: requests on `rq/<name>Request` with the
client guid and a sequence number before the request, replies taken from `rr/<name>Reply` where
the guid is ours, both endpoints carrying `clientid=...;` in their USER_DATA. No armfleet code
is imported.

Protocol: one JSON request per stdin line, one JSON reply per stdout line.
  {"op": "latest", "topic": "/tf", "type": "tf2_msgs/msg/TFMessage", "latched": false}
  {"op": "all", "topic": ..., "type": ...}          every sample received so far
  {"op": "publish", "topic": ..., "type": ..., "msg": {...}}
  {"op": "matched", "topic": ..., "type": ..., "role": "reader" | "writer"}
  {"op": "call", "service": "/x/_action/send_goal", "type": "pkg/action/X_SendGoal",
   "request": {...}, "timeout": 10}                 the decoded reply
"""

import time
import uuid

from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from tests import ros2_types
from tests.peer_stdio import serve_lines
from tests.ros2_participant import ANY, Participant


def qos(latched: bool, user_data: bytes = b"") -> Qos:
    policies = [
        Policy.Reliability.Reliable(max_blocking_time=100_000_000),
        Policy.Durability.TransientLocal if latched else Policy.Durability.Volatile,
        Policy.History.KeepLast(1 if latched else 100),
    ]
    if user_data:
        policies.append(Policy.Userdata(user_data))
    return Qos(*policies)


class Peer(Participant):
    def __init__(self) -> None:
        self.topics: dict[tuple[str, str, bool], Topic] = {}
        self.writers: dict[str, DataWriter] = {}
        self.samples: dict[str, list] = {}
        self.clients: dict[str, tuple] = {}
        self.seq = 0
        super().__init__()

    def _topic(self, dds_name: str, ros_type: str, header: bool = False) -> Topic:
        key = (dds_name, ros_type, header)
        if key not in self.topics:
            self.topics[key] = Topic(self.dp, dds_name, ros2_types.idl_type(ros_type, header))
        return self.topics[key]

    def writer(self, topic: str, ros_type: str) -> DataWriter:
        if topic not in self.writers:
            t = self._topic("rt" + topic, ros_type)
            self.writers[topic] = DataWriter(self.dp, t, qos=qos(False))
        return self.writers[topic]

    def reader(self, topic: str, ros_type: str, latched: bool) -> DataReader:
        with self.lock:
            if topic not in self.readers:
                t = self._topic("rt" + topic, ros_type)
                self.readers[topic] = (DataReader(self.dp, t, qos=qos(latched)), ros_type)
            return self.readers[topic][0]

    def received(self, topic: str, ros_type: str, raw: bytes) -> None:
        self.samples.setdefault(topic, []).append(ros2_types.deserialize(ros_type, raw))

    def client(self, service: str, ros_type: str) -> tuple:
        """rq/...Request writer and rr/...Reply reader, as rmw_cyclonedds creates a client."""
        if service not in self.clients:
            client_id = uuid.uuid4().bytes
            user = f"clientid={'.'.join(f'{b:x}' for b in client_id)};".encode()
            req_t = self._topic(f"rq{service}Request", f"{ros_type}_Request", True)
            rep_t = self._topic(f"rr{service}Reply", f"{ros_type}_Response", True)
            w = DataWriter(self.dp, req_t, qos=qos(False, user))
            r = DataReader(self.dp, rep_t, qos=qos(False, user))
            guid = int.from_bytes(client_id[:8], "little")
            self.clients[service] = (w, r, guid)
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and not (
                w.get_publication_matched_status().current_count
                and r.get_subscription_matched_status().current_count
            ):
                time.sleep(0.02)
        return self.clients[service]

    def call(self, service: str, ros_type: str, request: dict, timeout: float) -> object:
        w, r, guid = self.client(service, ros_type)
        self.seq += 1
        body = ros2_types.serialize(f"{ros_type}_Request", request)
        header = guid.to_bytes(8, "little") + self.seq.to_bytes(8, "little", signed=True)
        ddspy_write(w._ref, body[:4] + header + body[4:])
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for data, info in ddspy_take(r._ref, ANY, 16):
                raw = bytes(data)
                if not info.valid_data:
                    continue
                got_guid = int.from_bytes(raw[4:12], "little")
                got_seq = int.from_bytes(raw[12:20], "little", signed=True)
                if (got_guid, got_seq) == (guid, self.seq):
                    return ros2_types.deserialize(f"{ros_type}_Response", raw[:4] + raw[20:])
            time.sleep(0.005)
        return None

    def handle(self, req: dict) -> object:
        op, topic, kind = req["op"], req.get("topic", ""), req.get("type", "")
        if op == "publish":
            return ddspy_write(
                self.writer(topic, kind)._ref, ros2_types.serialize(kind, req["msg"])
            )
        if op in ("latest", "all"):
            self.reader(topic, kind, req.get("latched", False))
            got = self.samples.get(topic, [])
            return (got[-1] if got else None) if op == "latest" else got
        if op == "call":
            return self.call(req["service"], kind, req.get("request", {}), req.get("timeout", 10))
        if op == "matched":
            if req.get("role") == "reader":  # armfleet's reader: we write
                status = self.writer(topic, kind).get_publication_matched_status
            else:
                status = self.reader(
                    topic, kind, req.get("latched", False)
                ).get_subscription_matched_status
            deadline = time.monotonic() + req.get("timeout", 20)
            while not status().current_count and time.monotonic() < deadline:
                time.sleep(0.05)
            return status().current_count
        raise ValueError(f"unknown op {op!r}")


if __name__ == "__main__":
    serve_lines(Peer().handle)
