"""One world's topics in one namespace (`/world_N`, and the root for world 0).

In: `joint_commands` (sensor_msgs/JointState, the seed's message), `forward_position_controller/
commands` (std_msgs/Float64MultiArray, six arm joints), `scaled_joint_trajectory_controller/
joint_trajectory` and `joint_trajectory_controller/joint_trajectory` (trajectory_msgs/
JointTrajectory; no points = stop and hold). Out: `joint_states`, `tf`, `tf_static`,
`robot_description`, and `io_and_status_controller/safety_mode` (std_msgs/UInt8, UR's number:
1 NORMAL, 3 PROTECTIVE_STOP; latched, published when it changes, as UR's driver does; the
rulebook says why this type). A state topic costs nothing until something subscribes to it.
Made when the namespace opens (namespaces.py: the root at start, `/world_N` at its first use).
"""

from __future__ import annotations

import threading
from typing import Any

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String, UInt8
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory

from armfleet_ros import convert
from armfleet_ros.parts import QUIET_PUB, QUIET_SUB
from clients import ros_rules
from clients import trajectory as tj
from clients.errors import ArmfleetError

LATCHED = QoSProfile(
    depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)
TF_QOS = QoSProfile(depth=100)
# Commands: rclpy's default QoS (reliable, volatile) with a deep history, so that a burst the
# executor has not taken yet (1000/s, Isaac's 500 Hz) waits instead of being overwritten.
COMMAND_DEPTH = 1000


class WorldTopics:
    """The publishers and subscriptions of one world under one namespace."""

    def __init__(self, owner: Any, world: int, ns: str, part: Any) -> None:
        node = part.topics
        self.owner, self.world, self.ns = owner, world, ns
        group = part.group
        self.states = node.create_publisher(JointState, f"{ns}/joint_states", 10, **QUIET_PUB)
        self.tf = node.create_publisher(TFMessage, f"{ns}/tf", TF_QOS, **QUIET_PUB)
        self.tf_static = node.create_publisher(TFMessage, f"{ns}/tf_static", LATCHED, **QUIET_PUB)
        self.description = node.create_publisher(
            String, f"{ns}/robot_description", LATCHED, **QUIET_PUB
        )
        topic = f"{ns}/{ros_rules.SAFETY_MODE_TOPIC}"
        self.safety = node.create_publisher(UInt8, topic, LATCHED, **QUIET_PUB)
        self._safety_mode: int | None = None  # UR's number last published (None: none yet)
        self.tf_static.publish(owner.tree.static_message())
        self.description.publish(String(data=owner.urdf))
        self.subs = [
            node.create_subscription(
                JointState,
                f"{ns}/joint_commands",
                self._joint_command,
                COMMAND_DEPTH,
                callback_group=group,
                **QUIET_SUB,
            ),
            node.create_subscription(
                Float64MultiArray,
                f"{ns}/forward_position_controller/commands",
                self._forward_command,
                COMMAND_DEPTH,
                callback_group=group,
                **QUIET_SUB,
            ),
        ]
        for name in ros_rules.FJT_CONTROLLERS:
            topic = f"{ns}/{name}/joint_trajectory"
            self.subs.append(
                node.create_subscription(
                    JointTrajectory,
                    topic,
                    lambda msg, topic=topic: self._trajectory(msg, topic),
                    COMMAND_DEPTH,
                    callback_group=group,
                    **QUIET_SUB,
                )
            )
        self.listened_states = False
        self.listened_tf = False
        self.owed: int | None = None  # the tick of the last command acked, until published
        self._published = (-1, -1)  # (connection, tick) of the last state published
        self._lock = threading.Lock()

    def refresh(self) -> None:
        """Whether anyone subscribes to the state topics now (checked twice a second)."""
        self.listened_states = self.states.get_subscription_count() > 0
        self.listened_tf = self.tf.get_subscription_count() > 0

    # -- in ------------------------------------------------------------------------------------

    def _send(self, targets: dict[str, float], topic: str) -> None:
        fut = self.owner.link.set_targets(self.world, targets)
        fut.add_done_callback(lambda f: self._acked(f, topic))

    def _acked(self, fut: Any, topic: str) -> None:
        exc = fut.exception()
        if exc is None:
            self.owed = fut.result().tick  # its frame goes out first (node.py)
            self.owner.accepted += 1
        else:
            self.owner.bad.report("rejected", topic, str(exc))

    def _joint_command(self, msg: Any) -> None:
        topic = f"{self.ns}/joint_commands"
        try:
            targets = convert.joint_state_targets(self.owner.joints, msg.name, msg.position)
        except ros_rules.BadMessage as exc:
            self.owner.bad.report(exc.kind, topic, exc.detail)
            return
        self._send(targets, topic)

    def _forward_command(self, msg: Any) -> None:
        topic = f"{self.ns}/forward_position_controller/commands"
        try:
            targets = convert.forward_targets(self.owner.joints, msg.data)
        except ros_rules.BadMessage as exc:
            self.owner.bad.report(exc.kind, topic, exc.detail)
            return
        self._send(targets, topic)

    def _trajectory(self, msg: Any, topic: str) -> None:
        http = self.owner.http
        arm = self.owner.joints[: ros_rules.ARM_JOINTS]
        try:
            ros_rules.check_arm_joints(list(msg.joint_names), arm)
            if not msg.points:
                http.call(tj.cancel_call(self.world))  # no points: stop and hold
            else:
                http.call(tj.start_call(self.world, convert.trajectory_body(msg)))
        except ros_rules.BadMessage as exc:
            self.owner.bad.report(exc.kind, topic, exc.detail)
            return
        except ArmfleetError as exc:
            self.owner.bad.report("rejected", topic, str(exc))
            return
        self.owner.accepted += 1

    # -- out -----------------------------------------------------------------------------------

    def owed_by(self, tick: int) -> bool:
        """Whether a frame of `tick` shows a command just acked."""
        owed = self.owed
        return owed is not None and tick >= owed

    def publish(
        self, batch: Any, row: int, stamp: tuple[int, int], sec: int, nanosec: int, poses: Any
    ) -> None:
        """The world's state and moving `/tf` of a frame (any socket's thread), unless a newer
        frame's were published already: `stamp` is (connection, tick)."""
        with self._lock:
            if stamp <= self._published:
                return
            self._published = stamp
            if self.owed_by(stamp[1]):
                self.owed = None
            modes = batch.safety_mode  # None: a server before the safety block (all NORMAL)
            mode = ros_rules.safety_mode_number("NORMAL" if modes is None else modes[row])
            if mode != self._safety_mode:  # latched: a late subscriber gets the last one
                self._safety_mode = mode
                self.safety.publish(UInt8(data=mode))
            if self.listened_states:
                self.publish_state(batch, row, sec, nanosec)
            if poses is not None:
                self.tf.publish(self.owner.tree.moving_message(poses, sec, nanosec))

    def publish_state(self, batch: Any, row: int, sec: int, nanosec: int) -> None:
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        msg.name = list(batch.name)
        msg.position = batch.position[row].astype(float).tolist()
        msg.velocity = batch.velocity[row].astype(float).tolist()
        msg.effort = batch.effort[row].astype(float).tolist()
        self.states.publish(msg)
