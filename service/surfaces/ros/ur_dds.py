"""What the UR driver offers beside `joint_states`, on DDS, for every world namespace.

For world 0 at the root (as the seed uses it) and for `/world_N` per exposed world:
- `robot_description` (std_msgs/String, transient-local): the URDF of service/surfaces/ros/urdf.py;
- `tf_static` (transient-local, once) and `tf` (at the bridge's state rate while someone
  listens): the link frames of service/surfaces/ros/tf_frames.py, stamped with simulated time;
- `forward_position_controller/commands` (std_msgs/Float64MultiArray): six arm positions,
  through the control layer (source `ros2`) like any command;
- the controllers' actions and `~/joint_trajectory` topics (service/surfaces/ros/dds_actions.py).

It lives inside the DDS bridge (dds.py): same participant, the bridge's publisher
thread writes `tf`, and a reader thread of its own serves commands and action requests.
"""

from __future__ import annotations

import itertools
import math
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from service.surfaces.ros import dds_actions, topics
from service.surfaces.ros.goal_msgs import (
    ACTIONS,
    FJT_TYPE,
    GoalRejected,
    action_names,
    trajectory_spec,
)
from service.surfaces.ros.goals import runner_of
from service.surfaces.ros.tf_frames import FrameTree
from service.surfaces.ros.topics import ROS2, BadMessageCounter, TopicMap
from service.surfaces.ros.urdf import generate

if TYPE_CHECKING:
    from service.core.surface import SurfaceContext

FORWARD_COMMANDS = "forward_position_controller/commands"
# the joint trajectory controllers' fire-and-forget topic (`~/joint_trajectory`)
TRAJECTORY_TOPICS = tuple(
    name.replace("follow_joint_trajectory", "joint_trajectory")
    for name, kind in ACTIONS.items()
    if kind == FJT_TYPE
)
JOINT_TRAJECTORY_TYPE = "trajectory_msgs/msg/JointTrajectory"
STRING_TYPE = "std_msgs/msg/String"
TF_TYPE = "tf2_msgs/msg/TFMessage"
FLOAT64_ARRAY_TYPE = "std_msgs/msg/Float64MultiArray"
_READER_DEPTH = 100


def ur_topics(topic_map: TopicMap) -> dict[str, str]:
    """Topic name → ROS 2 type of every UR-driver topic (for `GET /v1/ros`)."""
    out = {}
    for ns in topic_map.namespaces():
        out[f"{ns}/robot_description"] = STRING_TYPE
        out[f"{ns}/tf"] = TF_TYPE
        out[f"{ns}/tf_static"] = TF_TYPE
        out[f"{ns}/{FORWARD_COMMANDS}"] = FLOAT64_ARRAY_TYPE
        out |= {f"{ns}/{name}": JOINT_TRAJECTORY_TYPE for name in TRAJECTORY_TOPICS}
    return out


def ur_actions(topic_map: TopicMap) -> dict[str, str]:
    """Action name → action type, every action of every namespace."""
    return {name: kind for name, (_, kind) in action_names(topic_map.namespaces()).items()}


def arm_command(arm_joints: list[str], data: list[float]) -> list[float]:
    """forward_position_controller's rule: exactly one finite position per arm joint."""
    if len(data) != len(arm_joints):
        raise topics.BadMessage(
            "length_mismatch",
            f"data needs {len(arm_joints)} positions ({', '.join(arm_joints)}), got {len(data)}",
        )
    for name, value in zip(arm_joints, data, strict=True):
        if not math.isfinite(value):
            raise topics.BadMessage("not_finite", f"data for {name} is {value} (must be finite)")
    return [float(v) for v in data]


class UrDriverDds:
    """The UR driver's topics (and actions) on an existing DDS participant."""

    def __init__(self, dp: Any, ctx: SurfaceContext, topic_map: TopicMap, bad: BadMessageCounter):
        from cyclonedds import core
        from cyclonedds.pub import DataWriter
        from cyclonedds.qos import Qos
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from service.surfaces.ros import msgs, msgs_action, msgs_tf
        from service.surfaces.ros.dds_actions import ActionServerDds
        from service.surfaces.ros.qos import latched as latched_qos
        from service.surfaces.ros.qos import rclpy_default as _qos

        loop = ctx.loop
        self._control = ctx.control
        self._bad = bad
        self._msgs, self._tf, self._traj = msgs, msgs_tf, msgs_action
        self.received = 0
        self._entities: list[Any] = []
        self.readers: list[Any] = []
        self.writers: list[Any] = []
        mjm = loop.batch.robot.mjm
        self.urdf = generate(mjm, loop.spec)
        self.frames = FrameTree(mjm)
        self._arm = [j.name for j in loop.spec.joints][:6]
        self._spaces = topic_map.namespaces()
        self._tick_dt = loop.batch.tick_dt

        made: dict[str, Any] = {}
        self._conditions: list[Any] = []

        def make(role: str, dds_name: str, kind: type, user: Any = None) -> Any:
            """A reader or writer on DDS topic `dds_name`: role reader / writer / latched."""
            if dds_name not in made:
                made[dds_name] = Topic(dp, dds_name, kind)
                self._entities.append(made[dds_name])
            qos = {
                "latched": latched_qos,
                "reader": lambda: _qos(_READER_DEPTH, accept_xcdr2=True),  # newer peers' XCDR2
                "writer": lambda: _qos(10),
            }[role]()
            if user is not None:
                qos = qos + Qos(user)
            if role == "reader":
                entity = DataReader(dp, made[dds_name], qos=qos)
                self.readers.append(entity)
                condition = core.ReadCondition(entity, any_sample)
                self._conditions.append(condition)
            else:
                entity = DataWriter(dp, made[dds_name], qos=qos)
                self.writers.append(entity)
            self._entities.append(entity)
            return entity

        self._tf_writers: list[tuple[Any, int]] = []
        self._inputs: list[Callable[[], bool]] = []
        sec, nanosec = topics.stamp(topics.sim_seconds(loop.latest, self._tick_dt))
        static = self._static_message(msgs.Time(sec=sec, nanosec=nanosec))
        any_sample = core.SampleState.Any | core.ViewState.Any | core.InstanceState.Any
        self.runner = runner_of(ctx)
        ids = itertools.count(1)
        prefix = dp.guid.bytes[:12]

        def service_id() -> bytes:
            """rmw_cyclonedds_cpp's client/service id: participant prefix + a counter, dotted."""
            raw = prefix + next(ids).to_bytes(4, "big")
            return ".".join([f"{raw[0]:02x}", *(f"{b:x}" for b in raw[1:])]).encode()

        self.actions: list[ActionServerDds] = []
        for ns, world in self._spaces.items():
            rt = topics.dds_name
            make("latched", rt(f"{ns}/robot_description"), msgs_tf.String).write(
                msgs_tf.String(data=self.urdf)
            )
            make("latched", rt(f"{ns}/tf_static"), msgs_tf.TFMessage).write(static)
            tf_writer = make("writer", rt(f"{ns}/tf"), msgs_tf.TFMessage)
            self._tf_writers.append((tf_writer, world))
            name = f"{ns}/{FORWARD_COMMANDS}"
            r = make("reader", rt(name), msgs_tf.Float64MultiArray)
            self._inputs.append(self._command_input(r, name, world))
            for controller in TRAJECTORY_TOPICS:
                name = f"{ns}/{controller}"
                r = make("reader", rt(name), msgs_action.JointTrajectory)
                self._inputs.append(self._trajectory_input(r, name, world))
            for action, kind in ACTIONS.items():
                server = ActionServerDds(
                    make, service_id, f"{ns}/{action}", kind, world, self.runner, bad
                )
                self.actions.append(server)
                self._inputs += server.inputs()
        self._tf_listened = topics.ListenedWriters(self._tf_writers)

        self._waitset = core.WaitSet(dp)
        self._guard = core.GuardCondition(dp)
        for condition in self._conditions:
            self._waitset.attach(condition)
        self._entities += self._conditions
        self._waitset.attach(self._guard)
        self._entities += [self._guard, self._waitset]
        self._running = True
        self._thread = threading.Thread(
            target=self._read_loop, name="armfleet-ros2-ur", daemon=True
        )
        self._thread.start()

    # -- tf -----------------------------------------------------------------------------------

    def _stamped(self, stamp: Any, parent: str, child: str, pos: Any, quat: Any) -> Any:
        m = self._tf
        w, x, y, z = (float(v) for v in quat)
        return m.TransformStamped(
            header=self._msgs.Header(stamp=stamp, frame_id=parent),
            child_frame_id=child,
            transform=m.Transform(
                translation=m.Vector3(*(float(v) for v in pos)),
                rotation=m.Quaternion(x=x, y=y, z=z, w=w),
            ),
        )

    def _static_message(self, stamp: Any) -> Any:
        return self._tf.TFMessage(
            transforms=[
                self._stamped(stamp, t.parent, t.child, t.pos, t.quat) for t in self.frames.static
            ]
        )

    def write(self, snap: Any, stamp: Any) -> None:
        """Publisher thread: `tf` of every namespace somebody listens to."""
        listened = self._tf_listened.current()
        if not listened:
            return
        worlds = [world for _, world in listened]
        pos, quat = self.frames.moving(snap.body_pos[worlds], snap.body_quat[worlds])
        parents, children = self.frames.moving_parents, self.frames.moving_children
        for i, (w, _) in enumerate(listened):
            transforms = [
                self._stamped(stamp, parents[k], children[k], pos[i, k], quat[i, k])
                for k in range(len(children))
            ]
            w.write(self._tf.TFMessage(transforms=transforms))

    # -- commands -----------------------------------------------------------------------------

    def _read_loop(self) -> None:
        """Serve every input as it arrives (commands, and action requests)."""
        while self._running:
            self._waitset.wait(1_000_000_000)
            for serve_one in self._inputs:
                while self._running and serve_one():
                    pass

    def _command_input(self, reader: Any, topic: str, world: int) -> Callable[[], bool]:
        def apply(msg: Any) -> None:
            values = arm_command(self._arm, list(msg.data))
            self._control.command_targets(world, self._arm, values, ROS2)

        return self._serving(reader, self._tf.Float64MultiArray, topic, apply)

    def _trajectory_input(self, reader: Any, topic: str, world: int) -> Callable[[], bool]:
        """`~/joint_trajectory`: start it (preempting any running one); no points: stop and hold."""

        def apply(msg: Any) -> None:
            if not msg.points:
                self._control.cancel_trajectory([world], ROS2)
                return
            body = {"trajectory": dds_actions.to_plain(msg)}
            try:
                spec = trajectory_spec(self._control.spec, self._arm, body)
            except GoalRejected as exc:
                raise topics.BadMessage("rejected", str(exc)) from None
            self._control.start_trajectory([world], spec, ROS2)

        return self._serving(reader, self._traj.JointTrajectory, topic, apply)

    def _serving(
        self, reader: Any, kind: type, topic: str, apply: Callable[[Any], None]
    ) -> Callable[[], bool]:
        """An input's server: take what `reader` holds and `apply` each message (bad ones are
        counted by `topics.take_commands`), count the accepted; True while any was taken."""

        def serve_one() -> bool:
            taken, accepted = topics.take_commands(reader, kind, topic, self._bad, apply)
            self.received += accepted
            return taken

        return serve_one

    def stop(self) -> None:
        """Leave the graph: the thread ends, then every entity of ours is deleted."""
        self._running = False
        self._guard.set(True)
        self._thread.join(timeout=5)
        for entity in reversed(self._entities):
            entity.__del__()
        self._entities.clear()
