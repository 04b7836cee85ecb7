"""Foxglove live: the worlds in Foxglove's 3D, plot and publish panels over its WebSocket protocol.

The Foxglove SDK (PyPI `foxglove-sdk`, a Rust core with its own threads) serves the
foxglove.websocket protocol. This surface publishes, for each shown world `w`:

- `/world_<w>/joint_states`: sensor_msgs/JointState-shaped JSON (header.stamp = simulated time;
  name, position [rad], velocity [rad/s], effort [N·m]), plottable as `.position[2]`;
- `/tf`: foxglove.FrameTransforms: `world` → `w<w>/world` (the worlds laid out on a grid so that
  they stand side by side) and `w<w>/world` → `w<w>/<body>` for every body;
- `/scene`: foxglove.SceneUpdate with the model's visible geoms (boxes, cylinders, capsules as a
  cylinder and two spheres, the floor) attached to those body frames (sent again on subscribe).

Clients may publish JSON JointState (`{"name": [...], "position": [...]}`) on `/joint_commands`
(world 0, as the seed's topic) or `/world_<w>/joint_commands`; it goes through the control layer
with source `foxglove`, so it is validated, clamped and recorded like any other command.
Foxglove's handshake has no place for a token, so a client presents one (the administrator's or
a lease's) by setting the parameter `armfleet.token`; the server keeps who that client is and
never publishes the value back. A command on a world its caller may not command is refused
by Control (service/core/access/callers.py) and reported in a status message naming the world.

A thread of its own samples the batch at `rate` Hz (one request to the loop per frame, served
between ticks) and does all encoding; the SDK keeps a bounded queue per client and drops the
oldest when a viewer is slow, so neither a slow nor a stuck client can slow the loop. Body poses
come from the full qpos through a host MuJoCo model (`mj_kinematics`), only for shown worlds.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from typing import TYPE_CHECKING, Any

import foxglove
import mujoco
import numpy as np
from foxglove import Capability, StatusLevel
from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel
from foxglove.messages import (
    FrameTransform,
    FrameTransforms,
    Quaternion,
    SceneUpdate,
    Timestamp,
    Vector3,
)

from service.core.access.callers import book_of
from service.core.errors import ArmfleetError
from service.core.sim.worlds import pick_worlds
from service.surfaces.foxglove.callers import TOKEN_PARAMETER, ClientCallers
from service.surfaces.foxglove.scene import geom_entities, quat_msg, vec_msg, world_offset

if TYPE_CHECKING:
    from foxglove.websocket import ChannelView, Client, ClientChannel

    from service.core.access.settings import AccessSettings
    from service.core.sim.types import Snapshot
    from service.core.surface import SurfaceContext

FOXGLOVE = "foxglove"  # the label of commands that came from a Foxglove client
log = logging.getLogger("armfleet.foxglove")

JOINT_STATE_SCHEMA = {
    "type": "object",
    "title": "sensor_msgs/msg/JointState",
    "properties": {
        "header": {
            "type": "object",
            "properties": {
                "stamp": {
                    "type": "object",
                    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
                },
                "frame_id": {"type": "string"},
            },
        },
        "name": {"type": "array", "items": {"type": "string"}},
        "position": {"type": "array", "items": {"type": "number"}},
        "velocity": {"type": "array", "items": {"type": "number"}},
        "effort": {"type": "array", "items": {"type": "number"}},
    },
}


class FoxgloveLive:
    """A surface: the Foxglove WebSocket server and the thread that feeds it."""

    name = "foxglove"

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 8765,
        worlds: str | None = None,
        rate: float = 30.0,
        commands: bool = True,
        cameras: tuple[str, float] = ("", 10.0),  # camera names, images a second
        access: AccessSettings | None = None,  # None: anyone may command (tests)
    ):
        self._host, self._port, self._worlds_spec = host, port, worlds
        self._cameras, self._camera_topics = cameras, None
        self._commands = commands
        self._callers = None if access is None else ClientCallers(access)
        self._period = 1.0 / rate
        self._stop = threading.Event()
        self._scene_wanted = threading.Event()
        self._thread: threading.Thread | None = None
        self._server: Any = None
        self._client_topics: dict[tuple[int, int], str] = {}
        self.frames = 0  # frames published (for /v1/info-style diagnostics and tests)

    @property
    def port(self) -> int:
        return int(self._server.port) if self._server is not None else self._port

    def start(self, ctx: SurfaceContext) -> None:
        loop, control = ctx.loop, ctx.control
        self._loop, self._control = loop, control
        self.worlds = pick_worlds(self._worlds_spec, loop.batch.nworld)
        self._names = list(loop.batch.spec.names)
        self._hz = float(loop.batch.control_hz)
        self._mjm = loop.batch.robot.mjm  # the scene served, the user's cell included
        self._data = mujoco.MjData(self._mjm)
        self._ctx = foxglove.Context()  # our own: channels of other servers stay apart
        self._joint_channels = {
            w: foxglove.Channel(
                f"/world_{w}/joint_states", schema=JOINT_STATE_SCHEMA, context=self._ctx
            )
            for w in self.worlds
        }
        self._tf = FrameTransformsChannel("/tf", context=self._ctx)
        self._scene = SceneUpdateChannel("/scene", context=self._ctx)
        names = [c.strip() for c in self._cameras[0].split(",") if c.strip()]
        if names and ctx.cameras is not None:  # camera_topics.py: images + calibrations
            from service.surfaces.foxglove.camera_topics import CameraTopics

            self._camera_topics = CameraTopics(
                self._ctx, ctx.cameras, self.worlds, names, self._cameras[1], self._hz
            )
            self._camera_topics.start()
        self._server = foxglove.start_server(
            name="armfleet",
            host=self._host,
            port=self._port,
            capabilities=[Capability.ClientPublish, Capability.Parameters]
            if self._commands
            else [],
            supported_encodings=["json"],
            server_listener=self,
            context=self._ctx,
        )
        self._scene_wanted.set()
        self._thread = threading.Thread(target=self._run, name="armfleet-foxglove", daemon=True)
        self._thread.start()
        log.info(
            "Foxglove WebSocket on ws://%s:%d: worlds %s at %.0f Hz (3D: frame `world`)%s",
            self._host,
            self.port,
            ",".join(map(str, self.worlds)),
            1 / self._period,
            "" if self._commands else "; view only",
        )

    def stop(self) -> None:
        if self._camera_topics is not None:
            self._camera_topics.stop()
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        if self._server is not None:
            self._server.stop()

    # -- the feeding thread ----------------------------------------------------------------

    def _run(self) -> None:
        next_due = time.monotonic()
        while not self._stop.is_set():
            if self._scene_wanted.is_set():
                self._scene_wanted.clear()
                self._publish_scene()
            if self._has_subscribers():
                try:
                    self._publish_frame()
                except Exception:  # a bad frame must not end the stream
                    log.exception("Foxglove frame failed")
            next_due = max(next_due + self._period, time.monotonic())
            self._stop.wait(max(0.0, next_due - time.monotonic()))

    def _has_subscribers(self) -> bool:
        chans = (self._tf, *self._joint_channels.values())
        return any(c.has_sinks() for c in chans)

    def _stamp(self, tick: int) -> tuple[int, Timestamp]:
        ns = round(tick * 1e9 / self._hz)
        return ns, Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)

    def _publish_frame(self) -> None:
        worlds = np.array(self.worlds)
        # One request served between ticks: the snapshot and full qpos of the same tick.
        snap, qpos = self._loop.call(lambda b: (b.snapshot(), b.qpos()[worlds])).result(timeout=5)
        ns, stamp = self._stamp(snap.tick)
        self._publish_joint_states(snap, ns)
        if not self._tf.has_sinks():
            return
        transforms = []
        m, d = self._mjm, self._data
        for i, w in enumerate(self.worlds):
            x, y = world_offset(i, len(self.worlds))
            transforms.append(
                FrameTransform(
                    timestamp=stamp,
                    parent_frame_id="world",
                    child_frame_id=f"w{w}/world",
                    translation=Vector3(x=x, y=y, z=0.0),
                    rotation=Quaternion(w=1.0),
                )
            )
            d.qpos[:] = qpos[i]
            mujoco.mj_kinematics(m, d)
            for b in range(1, m.nbody):
                transforms.append(
                    FrameTransform(
                        timestamp=stamp,
                        parent_frame_id=f"w{w}/world",
                        child_frame_id=f"w{w}/{m.body(b).name}",
                        translation=vec_msg(d.xpos[b]),
                        rotation=quat_msg(d.xquat[b]),
                    )
                )
        self._tf.log(FrameTransforms(transforms=transforms), log_time=time.time_ns())
        self.frames += 1

    def _publish_joint_states(self, snap: Snapshot, stamp_ns: int) -> None:
        sec, nsec = divmod(stamp_ns, 1_000_000_000)
        now = time.time_ns()
        for w, channel in self._joint_channels.items():
            if not channel.has_sinks():
                continue
            channel.log(
                {
                    "header": {"stamp": {"sec": sec, "nsec": nsec}, "frame_id": ""},
                    "name": self._names,
                    "position": snap.position[w].tolist(),
                    "velocity": snap.velocity[w].tolist(),
                    "effort": snap.effort[w].tolist(),
                },
                log_time=now,
            )

    def _publish_scene(self) -> None:
        _, stamp = self._stamp(0)
        entities = []
        for w in self.worlds:
            entities += geom_entities(self._mjm, f"w{w}", stamp)
        self._scene.log(SceneUpdate(entities=entities), log_time=time.time_ns())

    # -- ServerListener (SDK threads) ------------------------------------------------------

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        if channel.topic == "/scene":  # entities are sent once; a new viewer needs them again
            self._scene_wanted.set()

    def on_client_advertise(self, client: Client, channel: ClientChannel) -> None:
        self._client_topics[(client.id, channel.id)] = channel.topic

    def on_client_unadvertise(self, client: Client, client_channel_id: int) -> None:
        self._client_topics.pop((client.id, client_channel_id), None)

    def on_set_parameters(
        self, client: Client, parameters: list[Any], request_id: str | None = None
    ) -> list[Any]:
        """`armfleet.token`: who this client is from now on; answered with no parameters, so
        the token is never published to any client."""
        for p in parameters:
            if p.name == TOKEN_PARAMETER and self._callers is not None:
                try:
                    self._callers.present(client.id, p.get_value(), book_of(self._control))
                except ArmfleetError as exc:
                    self._server.publish_status(f"{TOKEN_PARAMETER}: {exc}", StatusLevel.Warning)
        return []

    def on_message_data(self, client: Client, client_channel_id: int, data: bytes) -> None:
        if not self._commands:
            return  # not offered (see __init__); refused even if a client sends anyway
        topic = self._client_topics.get((client.id, client_channel_id), "")
        try:
            world = self._command_world(topic)
            if world is None:
                return  # a topic we do not take commands on
            control = self._control
            if self._callers is not None:
                caller, limiter = self._callers.of(client.id, book_of(self._control))
                if limiter.take() != "ok":
                    raise ValueError(limiter.detail)
                control = control.acting_for(caller)
            msg = json.loads(data)
            if not isinstance(msg, dict):
                raise ValueError("a JointState message must be a JSON object")
            name, position = msg.get("name", []), msg.get("position", [])
            control.command_targets(world, name, position, FOXGLOVE)
        except (ArmfleetError, ValueError) as exc:
            log.warning("Foxglove command on %s refused: %s", topic, exc)
            self._server.publish_status(f"{topic}: {exc}", StatusLevel.Warning)

    def _command_world(self, topic: str) -> int | None:
        if topic == "/joint_commands":
            return 0
        parts = topic.strip("/").split("/")
        if len(parts) == 2 and parts[1] == "joint_commands" and parts[0].startswith("world_"):
            try:
                return int(parts[0][len("world_") :])
            except ValueError:
                raise ValueError(f"{parts[0]!r} is not world_<id>") from None
        return None
