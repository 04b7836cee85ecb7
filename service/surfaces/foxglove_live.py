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

A thread of its own samples the batch at `rate` Hz (one request to the loop per frame, served
between ticks) and does all encoding; the SDK keeps a bounded queue per client and drops the
oldest when a viewer is slow, so neither a slow nor a stuck client can slow the loop. Body poses
come from the full qpos through a host MuJoCo model (`mj_kinematics`), only for shown worlds.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from typing import TYPE_CHECKING, Any

import foxglove
import mujoco
import numpy as np
from foxglove import Capability, StatusLevel
from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    Timestamp,
    Vector3,
)

from service.core.errors import ArmfleetError
from service.core.worlds import pick_worlds

if TYPE_CHECKING:
    from foxglove.websocket import ChannelView, Client, ClientChannel

    from service.core.surface import SurfaceContext
    from service.core.types import Snapshot

FOXGLOVE = "foxglove"  # the label of commands that came from a Foxglove client
log = logging.getLogger("armfleet.foxglove")

SPACING = 2.5  # m between neighbouring worlds in the shared `world` frame
_VISIBLE_GROUPS = (0, 1, 2)  # MuJoCo's viewer shows these groups by default
_FLOOR_HALF = 1.2  # m: the (infinite) floor plane drawn as a square tile per world

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


def world_offset(index: int, count: int) -> tuple[float, float]:
    """Where the `index`-th shown world stands in the shared frame (a square-ish grid)."""
    cols = max(1, math.ceil(math.sqrt(count)))
    return (index % cols) * SPACING, (index // cols) * SPACING


def _quat(wxyz: np.ndarray) -> Quaternion:
    return Quaternion(x=float(wxyz[1]), y=float(wxyz[2]), z=float(wxyz[3]), w=float(wxyz[0]))


def _vec(xyz: Any) -> Vector3:
    return Vector3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))


def _pose(pos: Any, wxyz: Any) -> Pose:
    return Pose(position=_vec(pos), orientation=_quat(np.asarray(wxyz)))


def geom_entities(mjm: mujoco.MjModel, prefix: str, stamp: Timestamp) -> list[SceneEntity]:
    """One SceneEntity per body with visible geoms, in the body's frame `<prefix>/<body>`."""
    per_body: dict[int, dict[str, list[Any]]] = {}
    for g in range(mjm.ngeom):
        if mjm.geom_group[g] not in _VISIBLE_GROUPS:
            continue
        rgba = mjm.mat_rgba[mjm.geom_matid[g]] if mjm.geom_matid[g] >= 0 else mjm.geom_rgba[g]
        if rgba[3] == 0:
            continue
        color = Color(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))
        size, pos, quat = mjm.geom_size[g], mjm.geom_pos[g], mjm.geom_quat[g]
        prims = per_body.setdefault(
            int(mjm.geom_bodyid[g]), {"cubes": [], "cylinders": [], "spheres": []}
        )
        kind = mujoco.mjtGeom(int(mjm.geom_type[g]))
        if kind == mujoco.mjtGeom.mjGEOM_BOX:
            prims["cubes"].append(
                CubePrimitive(pose=_pose(pos, quat), size=_vec(2 * size), color=color)
            )
        elif kind == mujoco.mjtGeom.mjGEOM_PLANE:
            tile = (2 * _FLOOR_HALF, 2 * _FLOOR_HALF, 0.002)
            prims["cubes"].append(
                CubePrimitive(pose=_pose(pos, quat), size=_vec(tile), color=color)
            )
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            prims["spheres"].append(
                SpherePrimitive(pose=_pose(pos, quat), size=_vec([2 * size[0]] * 3), color=color)
            )
        elif kind in (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE):
            r, half = float(size[0]), float(size[1])
            prims["cylinders"].append(
                CylinderPrimitive(
                    pose=_pose(pos, quat),
                    size=_vec((2 * r, 2 * r, 2 * half)),
                    bottom_scale=1.0,
                    top_scale=1.0,
                    color=color,
                )
            )
            if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
                for sign in (-1.0, 1.0):
                    end = np.zeros(3)
                    mujoco.mju_rotVecQuat(end, np.array([0.0, 0.0, sign * half]), quat)
                    prims["spheres"].append(
                        SpherePrimitive(
                            pose=_pose(pos + end, quat), size=_vec([2 * r] * 3), color=color
                        )
                    )
    out = []
    for body, p in sorted(per_body.items()):
        name = mjm.body(body).name
        out.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=f"{prefix}/{name}",
                id=f"{prefix}/{name}",
                frame_locked=True,
                cubes=p["cubes"],
                cylinders=p["cylinders"],
                spheres=p["spheres"],
            )
        )
    return out


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
    ):
        self._host, self._port, self._worlds_spec = host, port, worlds
        # Foxglove's protocol has no place for our token: where writes need one, the server
        # offers no ClientPublish and is a viewer only (commands go through HTTP/WS instead).
        self._commands = commands
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
        self._server = foxglove.start_server(
            name="armfleet",
            host=self._host,
            port=self._port,
            capabilities=[Capability.ClientPublish] if self._commands else [],
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
            "" if self._commands else "; view only: writes need the token",
        )

    def stop(self) -> None:
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
                        translation=_vec(d.xpos[b]),
                        rotation=_quat(d.xquat[b]),
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

    def on_message_data(self, client: Client, client_channel_id: int, data: bytes) -> None:
        if not self._commands:
            return  # not offered (see __init__); refused even if a client sends anyway
        topic = self._client_topics.get((client.id, client_channel_id), "")
        try:
            world = self._command_world(topic)
            if world is None:
                return  # a topic we do not take commands on
            msg = json.loads(data)
            if not isinstance(msg, dict):
                raise ValueError("a JointState message must be a JSON object")
            name, position = msg.get("name", []), msg.get("position", [])
            self._control.command_targets(world, name, position, FOXGLOVE)
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
