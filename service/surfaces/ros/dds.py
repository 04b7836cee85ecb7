"""The ROS 2 bridge over DDS: armfleet as a participant of the ROS 2 graph, without ROS.

Eclipse Cyclone DDS (the middleware behind rmw_cyclonedds_cpp) carries the ROS 2 topics with the
names and types a ROS 2 node uses (`rt/joint_commands`, `sensor_msgs::msg::dds_::JointState_`)
and rclpy-compatible QoS, so the seed's rclpy controller drives world 0 unchanged and
`ros2 topic echo /joint_states` shows the arm.

Two threads of its own, never the event loop or the sim thread:
- the reader thread waits on a WaitSet over the command readers and hands each JointState to
  the control layer (source `ros2`), which validates, clamps and stages it like any command;
- the publisher thread writes `/joint_states`, `/world_N/joint_states` and `/clock` from the
  newest snapshot. The loop sees the bridge as a snapshot sink that only stores a reference.

DDS stays on loopback unless the user opens it, like the HTTP bind; discovery.py
says how (and why every ROS 2 node on the machine finds it whichever starts first).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any

from service.core.types import Snapshot
from service.core.worlds import world_list
from service.surfaces.ros import topics
from service.surfaces.ros.discovery import LOOPBACK_CONFIG, DdsConfig, choose_config
from service.surfaces.ros.qos import rclpy_default as _qos
from service.surfaces.ros.topics import ROS2, BadMessageCounter, TopicMap
from service.surfaces.ros.ur_dds import ur_actions, ur_topics

if TYPE_CHECKING:
    from service.core.surface import SurfaceContext

log = logging.getLogger("armfleet.ros2")

__all__ = ["LOOPBACK_CONFIG", "DdsBridge", "DdsConfig", "choose_config"]

NODE_NAME = "armfleet"  # how ROS 2 tools name the bridge (`ros2 node list` shows /armfleet)
# Commands buffered per topic while the reader thread waits for a core (a busy machine can hold
# it off for a while); rclpy's depth 10 would drop commands under a burst.
_READER_DEPTH = 1000
_TAKE_BATCH = 64
_MATCH_CHECK_S = 0.5  # a new subscriber gets its first state within this


class DdsBridge:
    """A surface: `start(ctx)` joins the graph, `stop()` leaves it."""

    name = "ros2"

    def __init__(
        self,
        rate: float = 60.0,
        worlds: str | None = None,
        network: bool = False,
        cameras: tuple[str, float] = ("", 10.0),  # camera names, images a second
    ):
        if not 0 < rate <= 1000:
            raise ValueError(f"ros2_rate must be in (0, 1000] Hz, got {rate}")
        self.rate = rate
        self._worlds_spec = worlds
        self._network = network
        self._camera_names = [c.strip() for c in cameras[0].split(",") if c.strip()]
        self._camera_rate = cameras[1]
        self.cameras: Any = None  # camera_dds.RosCameras when --ros2-cameras names some
        self.config: DdsConfig | None = None
        self.topics: TopicMap | None = None
        self.bad = BadMessageCounter("ros2")
        self.received = 0  # commands accepted by the control layer
        self.published = 0  # JointState samples written
        self._period = 1.0 / rate
        self._next_due = 0.0
        self._cond = threading.Condition()
        self._latest: Snapshot | None = None
        self._running = False
        self._threads: list[threading.Thread] = []
        self._entities: list[Any] = []  # DDS entities, deleted children first on stop

    # -- life cycle -------------------------------------------------------------------------

    def start(self, ctx: SurfaceContext) -> None:
        from cyclonedds.core import (
            GuardCondition,
            InstanceState,
            ReadCondition,
            SampleState,
            ViewState,
            WaitSet,
        )
        from cyclonedds.domain import Domain, DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from service.surfaces.ros import msgs

        loop, control = ctx.loop, ctx.control
        self._control = control
        self._joints = tuple(loop.spec.names)
        self._joint_list = list(self._joints)
        self._tick_dt = loop.batch.tick_dt
        self.topics = TopicMap(world_list(self._worlds_spec, loop.batch.nworld, "ros2_worlds"))
        self.config = cfg = choose_config(self._network)
        if cfg.config is not None:
            self._entities.append(Domain(cfg.domain_id, cfg.config))
        dp = DomainParticipant(cfg.domain_id)
        self._entities.append(dp)

        def topic(name: str, kind: type) -> Any:
            t = Topic(dp, topics.dds_name(name), kind)
            self._entities.append(t)
            return t

        self._readers: list[tuple[Any, str, int]] = []
        for name, world in self.topics.command_topics().items():
            r = DataReader(
                dp, topic(name, msgs.JointState), qos=_qos(_READER_DEPTH, accept_xcdr2=True)
            )
            self._entities.append(r)
            self._readers.append((r, name, world))
        self._writers: list[tuple[Any, int]] = []
        for name, world in self.topics.state_topics().items():
            w = DataWriter(dp, topic(name, msgs.JointState), qos=_qos(10))
            self._entities.append(w)
            self._writers.append((w, world))
        self._listened = topics.ListenedWriters(self._writers, _MATCH_CHECK_S)
        self._clock = DataWriter(dp, topic(topics.CLOCK_TOPIC, msgs.Clock), qos=_qos(1))
        self._entities.append(self._clock)
        self._msgs = msgs
        from service.surfaces.ros.ur_dds import UrDriverDds

        self.ur = UrDriverDds(dp, ctx, self.topics, self.bad)
        if self._camera_names and ctx.cameras is not None:
            from service.surfaces.ros.camera_dds import RosCameras

            self.cameras = RosCameras(dp, ctx, self.topics, self._camera_names, self._camera_rate)
        self._announce_node(dp, msgs)

        self._waitset = WaitSet(dp)
        self._guard = GuardCondition(dp)
        any_sample = SampleState.Any | ViewState.Any | InstanceState.Any
        for r, _, _ in self._readers:
            condition = ReadCondition(r, any_sample)  # set while the reader holds samples
            self._waitset.attach(condition)
            self._entities.append(condition)
        self._waitset.attach(self._guard)
        self._entities += [self._guard, self._waitset]

        self._running = True
        self._threads = [
            threading.Thread(target=self._read_loop, name="armfleet-ros2-in", daemon=True),
            threading.Thread(target=self._publish_loop, name="armfleet-ros2-out", daemon=True),
        ]
        for t in self._threads:
            t.start()
        loop.add_sink(self)
        self._loop = loop
        log.info(
            "ROS 2 (DDS domain %d, %s): commands on %s; states on %s at %.0f Hz; /clock",
            cfg.domain_id,
            cfg.scope,
            ", ".join(self.topics.command_topics()),
            ", ".join(self.topics.state_topics()),
            self.rate,
        )

    def _announce_node(self, dp: Any, msgs: Any) -> None:
        """Name our readers and writers as node `/armfleet` on `ros_discovery_info`.

        ROS 2 tools learn node names from this rmw topic (`ros2 node list`, the node column of
        `ros2 topic info -v`); topics work without it. Transient-local, so late joiners get it.
        """
        from cyclonedds.pub import DataWriter
        from cyclonedds.qos import Policy, Qos
        from cyclonedds.topic import Topic

        def gid(entity: Any) -> Any:
            return msgs.Gid(list(entity.get_guid().bytes) + [0] * 8)

        info = msgs.ParticipantEntitiesInfo(
            gid=gid(dp),
            node_entities_info_seq=[
                msgs.NodeEntitiesInfo(
                    node_namespace="/",
                    node_name=NODE_NAME,
                    reader_gid_seq=[gid(r) for r, _, _ in self._readers]
                    + [gid(r) for r in self.ur.readers],
                    writer_gid_seq=[gid(w) for w, _ in self._writers]
                    + [gid(w) for w in [self._clock, *self.ur.writers]],
                )
            ],
        )
        qos = Qos(
            Policy.Reliability.Reliable(max_blocking_time=0),
            Policy.Durability.TransientLocal,
            Policy.History.KeepLast(1),
            Policy.DataRepresentation(use_cdrv0_representation=True),
        )
        topic = Topic(dp, "ros_discovery_info", msgs.ParticipantEntitiesInfo)
        writer = DataWriter(dp, topic, qos=qos)
        self._entities += [topic, writer]
        writer.write(info)

    def stop(self) -> None:
        if not self._running:
            return
        self._loop.remove_sink(self)
        with self._cond:
            self._running = False
            self._cond.notify_all()
        self._guard.set(True)
        for t in self._threads:
            t.join(timeout=5)
        self.ur.stop()
        if self.cameras is not None:
            self.cameras.stop()
        # cyclonedds keeps every entity in a class-level table until it is deleted explicitly.
        for entity in reversed(self._entities):
            entity.__del__()
        self._entities.clear()

    def status(self) -> dict[str, Any]:
        """What GET /v1/ros shows for DDS."""
        cfg = self.config
        return {
            "enabled": self._running,
            "domain_id": cfg.domain_id if cfg else None,
            "scope": cfg.scope if cfg else None,
            "rate_hz": self.rate,
            "topics": (
                self.topics.all_topics()
                | ur_topics(self.topics)
                | (self.cameras.topic_types if self.cameras else {})
            )
            if self.topics
            else {},
            "actions": ur_actions(self.topics) if self.topics else {},
            "commands_accepted": self.received + (self.ur.received if self._running else 0),
            "states_published": self.published,
            "rejected": self.bad.counts(),
        }

    # -- snapshot sink (sim thread: store a reference, nothing more) -------------------------

    def wants_snapshot(self, now: float) -> bool:
        return self._running and now >= self._next_due - 0.1 * self._period

    def publish(self, snapshot: Snapshot) -> None:
        # Every snapshot is kept (newest wins), also ones taken for other sinks: the publisher
        # thread paces itself, so the last state before a pause is always published.
        now = time.monotonic()
        if now >= self._next_due - 0.1 * self._period:
            self._next_due = max(self._next_due + self._period, now)
        with self._cond:
            self._latest = snapshot
            self._cond.notify()

    # -- threads ----------------------------------------------------------------------------

    def _read_loop(self) -> None:
        while self._running:
            self._waitset.wait(1_000_000_000)
            for reader, name, world in self._readers:
                while self._running and self._take(reader, name, world):
                    pass

    def _take(self, reader: Any, topic: str, world: int) -> bool:
        """Take up to a batch of commands and apply each in order; False when none were left."""

        def apply(msg: Any) -> None:
            self._control.command_targets(world, list(msg.name), list(msg.position), ROS2)

        taken, accepted = topics.take_commands(
            reader, self._msgs.JointState, topic, self.bad, apply
        )
        self.received += accepted
        return taken

    def _publish_loop(self) -> None:
        """Write the newest snapshot, then rest about one period: at most ~`rate` per second."""
        last_tick = -1
        while True:
            with self._cond:
                while self._running and (self._latest is None or self._latest.tick == last_tick):
                    self._cond.wait()
                if not self._running:
                    return
                snap = self._latest
            started = time.monotonic()
            try:
                self._write_states(snap)
            except Exception:  # a DDS error must not end the stream; the next snapshot retries
                log.exception("ROS 2 publish failed")
            last_tick = snap.tick
            # 10% slack as in the stream hub: a 60 Hz stream on a jittery 60 Hz loop takes
            # every tick instead of sitting one out now and then
            rest = started + 0.9 * self._period - time.monotonic()
            with self._cond:
                self._cond.wait_for(lambda: not self._running, rest)

    def _write_states(self, snap: Snapshot) -> None:
        msgs = self._msgs
        sec, nanosec = topics.stamp(topics.sim_seconds(snap, self._tick_dt))
        stamp = msgs.Time(sec=sec, nanosec=nanosec)
        self._clock.write(msgs.Clock(clock=stamp))
        for writer, world in self._listened.current():
            writer.write(
                msgs.JointState(
                    header=msgs.Header(stamp=stamp, frame_id=""),
                    name=self._joint_list,
                    position=snap.position[world].tolist(),
                    velocity=snap.velocity[world].tolist(),
                    effort=snap.effort[world].tolist(),
                )
            )
            self.published += 1
        self.ur.write(snap, stamp)
