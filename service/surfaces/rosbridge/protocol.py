"""The rosbridge v2 protocol (the subset ROS web and script clients use) on the service's port.

roslibpy's `Ros('localhost', 8000)` dials `ws://localhost:8000/` and roslib.js takes any URL, so
the socket is served at `/` (beside the browser page's GET) and at `/rosbridge`. The topics are
the armfleet_ros node's (topics.py); commands go through the control layer
(source `rosbridge`); states come from the stream hub with its latest-state delivery, so a slow
client skips frames instead of queueing them, and every client subscribed to a topic shares one
serialisation per tick.

Replies (`service_response`, `status`) are never dropped; a client that sends faster than it
reads its replies stops being read. Bad input gets a `status` frame with level `error` (and the
`id` when there was one) or a `service_response` with `result: false`; the socket stays open.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import orjson
from fastapi import WebSocket

from clients.ros_rules import BadMessage, RefusalCounter
from service.core.access import policy as access
from service.core.access import rates
from service.core.access.callers import book_of
from service.core.errors import ArmfleetError, Forbidden
from service.core.sim.rules import BadJointState
from service.core.sim.types import Snapshot
from service.core.streams.formats import FrameFormat
from service.core.streams.hub import StreamHub, Subscription
from service.core.surface import SurfaceContext
from service.surfaces.rosbridge import actions as rosbridge_actions
from service.surfaces.rosbridge import rosapi, sim_entities, topics
from service.surfaces.rosbridge.base import ROSBRIDGE, ProtocolError, same_type, topic_name
from service.surfaces.rosbridge.frames import (
    KINDS,
    LATCHED,
    TF_TYPE,
    RobotFrames,
    frame_topic,
)
from service.surfaces.rosbridge.topics import (
    CLOCK_TOPIC,
    CLOCK_TYPE,
    JOINT_STATE_TYPE,
    SAFETY_MODE_TYPE,
    TopicMap,
)

log = logging.getLogger("armfleet.rosbridge")

_JOINT_STATE_FIELDS = frozenset({"header", "name", "position", "velocity", "effort"})


@dataclass
class _TopicSub:
    """One client's subscription to one topic: the hub subscription and the ids that hold it."""

    hub_sub: Subscription
    ids: dict[Any, int] = field(default_factory=dict)  # subscribe id → throttle_rate [ms]
    # a topic sent only when it changes (the safety mode): what its message says, and the last
    # value sent (None: nothing yet, so a new subscriber gets the current one, as latched)
    changes: Callable[[Snapshot], Any] | None = None
    sent: Any = None


class RosbridgeServer:
    """Shared by every rosbridge client of one service: the topic map, counters."""

    def __init__(self, topic_map: TopicMap | None = None, max_rate: float = 60.0) -> None:
        self.topic_map = topic_map or TopicMap(())
        self.max_rate = max_rate  # states go out at most this often, like the ROS 2 node
        self.bad = RefusalCounter("rosbridge", log.warning)
        self.accepted = 0
        self.clients = 0
        self.frames: RobotFrames | None = None  # the robot topics' renderer, made on first use

    def status(self) -> dict[str, Any]:
        return {
            "clients": self.clients,
            "topics": self.topic_map.all_topics(),
            "commands_accepted": self.accepted,
            "rejected": self.bad.counts(),
        }


class Session:
    """One rosbridge client: its subscriptions, advertisements and outbox."""

    def __init__(self, ws: WebSocket, server: RosbridgeServer, ctx: SurfaceContext) -> None:
        assert ctx.hub is not None  # the service's context always has one
        self.ws = ws
        self.server = server
        self.ctx = ctx
        self.loop = ctx.loop
        self.hub: StreamHub = ctx.hub
        settings = ctx.access
        # One access policy for every surface (core/access/policy.py): may it publish, how fast;
        # which worlds: Control checks each command for this socket's caller (access/callers.py).
        self.grant = access.check_websocket(settings, ws, book_of(ctx.control))
        self.control = ctx.control.acting_for(self.grant.caller)
        self.joints = tuple(self.loop.spec.names)
        self.tick_dt = self.loop.batch.tick_dt
        self.replies: deque[bytes] = deque()
        self.subs: dict[str, _TopicSub] = {}
        self.advertised: dict[str, str] = {}
        self.ready = asyncio.Event()
        self.limiter = rates.RateLimiter(settings.command_rate, settings.command_burst)
        self.over_rate = False  # set when the client kept publishing over its rate: close 1008

    # -- inbound ----------------------------------------------------------------------------

    def handle_text(self, text: str) -> None:
        """One client frame → state changes and/or queued replies. Never raises."""
        msg_id: Any = None
        op: Any = None
        try:
            try:
                msg = orjson.loads(text)
            except orjson.JSONDecodeError as exc:
                raise ProtocolError(f"malformed JSON: {exc}") from None
            if not isinstance(msg, dict):
                raise ProtocolError("a message must be a JSON object with an `op`")
            msg_id = msg.get("id")
            op = msg.get("op")
            handler = _OPS.get(op) if isinstance(op, str) else None
            if handler is None:
                raise ProtocolError(f"op: unknown operation {op!r}; supported: {sorted(_OPS)}")
            handler(self, msg)
        except BadMessage as exc:
            self.server.bad.report(exc.kind, str(msg.get("topic")), exc.detail)
            self.status("error", f"{op}: {exc.kind}: {exc.detail}", msg_id)
        except ProtocolError as exc:
            self.server.bad.report("protocol", str(op), str(exc))
            self.status("error", f"{op}: {exc}" if op else str(exc), msg_id)

    def status(self, level: str, text: str, msg_id: Any = None) -> None:
        frame: dict[str, Any] = {"op": "status", "level": level, "msg": text}
        if msg_id is not None:
            frame["id"] = msg_id
        self._reply(frame)

    def _reply(self, frame: dict[str, Any]) -> None:
        self.replies.append(orjson.dumps(frame))
        self.ready.set()

    # -- ops --------------------------------------------------------------------------------

    def op_advertise(self, msg: dict[str, Any]) -> None:
        topic = topic_name(msg.get("topic"))
        kind = msg.get("type")
        if not isinstance(kind, str):
            raise ProtocolError("type: a message type (string) is required")
        if topic not in self.server.topic_map.command_topics():
            raise ProtocolError(
                f"topic: armfleet takes commands on {list(self.server.topic_map.command_topics())}"
                f", not {topic}"
            )
        if not same_type(kind, JOINT_STATE_TYPE):
            raise ProtocolError(f"type: {topic} carries {JOINT_STATE_TYPE}, not {kind!r}")
        self.advertised[topic] = kind

    def op_unadvertise(self, msg: dict[str, Any]) -> None:
        topic = topic_name(msg.get("topic"))
        if self.advertised.pop(topic, None) is None:
            raise ProtocolError(f"topic: {topic} was not advertised by this client")

    def op_publish(self, msg: dict[str, Any]) -> None:
        if not self.grant.command:
            raise BadMessage("refused", self.grant.reason)
        verdict = self.limiter.take()
        if verdict != "ok":
            self.over_rate = verdict == "close"
            raise BadMessage("refused", self.limiter.detail)
        topic = topic_name(msg.get("topic"))
        world = self.server.topic_map.command_topics().get(topic)
        if world is None:
            raise ProtocolError(
                f"topic: armfleet takes commands on {list(self.server.topic_map.command_topics())}"
                f", not {topic}"
            )
        body = msg.get("msg")
        if not isinstance(body, dict):
            raise BadMessage("bad_type", "msg must be a JSON object (a sensor_msgs/JointState)")
        unknown = sorted(set(body) - _JOINT_STATE_FIELDS)
        if unknown:
            raise BadMessage("unknown_field", f"JointState has no field {unknown[0]!r}")
        name, position = body.get("name", []), body.get("position", [])
        try:  # the JointState rule of every surface (clients/ros_rules.py, as the node's)
            self.control.command_targets(world, name, position, ROSBRIDGE)
        except BadJointState as exc:
            raise BadMessage(exc.reason, str(exc)) from None
        except Forbidden as exc:
            raise BadMessage("forbidden", str(exc)) from None
        except ArmfleetError as exc:
            raise BadMessage("rejected", str(exc)) from None
        self.server.accepted += 1

    def op_subscribe(self, msg: dict[str, Any]) -> None:
        topic = topic_name(msg.get("topic"))
        robot = frame_topic(self.server.topic_map.namespaces(), topic)
        if robot is not None and robot[1] in LATCHED:  # sent once, as transient-local is
            self._check_type(topic, KINDS[robot[1]], msg.get("type"))
            self.replies.append(self._frames().latched(topic, robot[1]))
            self.ready.set()
            return
        _, _, kind = self._renderer(topic)  # unknown topics fail here, before any change
        self._check_type(topic, kind, msg.get("type"))
        throttle = msg.get("throttle_rate", 0)
        queue_length = msg.get("queue_length", 0)
        for value, what in ((throttle, "throttle_rate"), (queue_length, "queue_length")):
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ProtocolError(f"{what}: a non-negative integer is required, got {value!r}")
        compression = msg.get("compression", "none")
        if compression not in (None, "none"):
            raise ProtocolError(f"compression: only 'none' is supported, not {compression!r}")
        existing = self.subs.get(topic)
        ids = dict(existing.ids) if existing else {}
        ids[msg.get("id")] = throttle
        self._deliver(topic, ids)

    @staticmethod
    def _check_type(topic: str, kind: str, given: Any) -> None:
        if given is not None and (not isinstance(given, str) or not same_type(given, kind)):
            raise ProtocolError(f"type: {topic} carries {kind}, not {given!r}")

    def _frames(self) -> RobotFrames:
        if self.server.frames is None:
            self.server.frames = RobotFrames(self.loop)
        return self.server.frames

    def op_unsubscribe(self, msg: dict[str, Any]) -> None:
        topic = topic_name(msg.get("topic"))
        existing = self.subs.get(topic)
        if existing is None:
            return  # rosbridge ignores unsubscribing what was not subscribed
        msg_id = msg.get("id")
        if msg_id is None:
            ids: dict[Any, int] = {}  # no id: every subscription of this client to the topic
        elif msg_id in existing.ids:
            ids = {k: v for k, v in existing.ids.items() if k != msg_id}
        else:
            return  # an id this client never subscribed with changes nothing
        self._deliver(topic, ids)

    def _deliver(self, topic: str, ids: dict[Any, int]) -> None:
        """Send `topic` at the fastest rate its subscribe ids ask for; none left: stop sending."""
        existing = self.subs.pop(topic, None)
        if not ids:
            if existing is not None:
                self.hub.remove(existing.hub_sub)
            return
        rate = self._rate(min(ids.values()))
        if existing is not None and existing.hub_sub.period == 1.0 / rate:
            existing.ids = ids
            self.subs[topic] = existing
            return
        if existing is not None:
            self.hub.remove(existing.hub_sub)
        render, world, _ = self._renderer(topic)
        fmt = FrameFormat.rosbridge(topic)
        # one writer per socket wakes for replies and any topic: the socket's `ready`
        sub = Subscription(np.array([world]), rate, fmt, render, ready=self.ready)
        changes = None
        if topic in self.server.topic_map.safety_topics():
            changes = lambda s: topics.safety_mode_dict(s, world)  # noqa: E731
        self.subs[topic] = _TopicSub(sub, ids, changes)
        self.hub.add(sub)
        if existing is None:
            sub.offer(self.loop.latest, time.monotonic())  # the current state at once

    def op_call_service(self, msg: dict[str, Any]) -> None:
        name = topic_name(msg.get("service"), "service")
        args = msg.get("args") or {}
        reply: dict[str, Any] = {"op": "service_response", "service": name}
        if msg.get("id") is not None:
            reply["id"] = msg["id"]
        entity = sim_entities.match(name, self.loop.batch.nworld)
        if entity is not None:  # simulation_interfaces: a get replies once the engine is read
            kind, world = entity
            if kind == "set":
                values = sim_entities.set_state(self, world, args)
                self._reply({**reply, "values": values, "result": True})
            else:
                sim_entities.get_state(
                    self, world, args, lambda v: self._reply({**reply, "values": v, "result": True})
                )
            return
        service = rosapi.find(name)
        if service is None:
            self.server.bad.report("unknown_service", name, "no such service")
            self._reply({**reply, "values": f"Service {name} does not exist", "result": False})
            return
        try:
            values = service(self, args)
        except ProtocolError as exc:
            self.server.bad.report("bad_args", name, str(exc))
            self._reply({**reply, "values": str(exc), "result": False})
            return
        self._reply({**reply, "values": values, "result": True})

    def op_set_level(self, msg: dict[str, Any]) -> None:
        """Accepted and ignored: armfleet's status frames are errors only."""

    # -- outbound ---------------------------------------------------------------------------

    def _rate(self, throttle_ms: int) -> float:
        """A subscription's rate [Hz]: its throttle, capped at the server's state rate."""
        if throttle_ms <= 0:
            return self.server.max_rate
        return min(1000.0 / throttle_ms, self.server.max_rate)

    def _renderer(self, topic: str) -> tuple[Callable[[Snapshot], bytes], int, str]:
        tick_dt, joints = self.tick_dt, self.joints
        if topic == CLOCK_TOPIC:

            def clock(s: Snapshot) -> bytes:
                body = topics.clock_dict(topics.sim_seconds(s, tick_dt))
                return orjson.dumps({"op": "publish", "topic": topic, "msg": body})

            return clock, 0, CLOCK_TYPE
        robot = frame_topic(self.server.topic_map.namespaces(), topic)
        if robot is not None and robot[1] == "tf":
            return self._frames().tf(topic, robot[0], tick_dt), robot[0], TF_TYPE
        safety = self.server.topic_map.safety_topics().get(topic)
        if safety is not None:

            def safety_mode(s: Snapshot) -> bytes:
                body = topics.safety_mode_dict(s, safety)
                return orjson.dumps({"op": "publish", "topic": topic, "msg": body})

            return safety_mode, safety, SAFETY_MODE_TYPE
        world = self.server.topic_map.state_topics().get(topic)
        if world is None:
            if topic in self.server.topic_map.command_topics():
                raise ProtocolError(
                    f"topic: {topic} is armfleet's input; subscribe to its state topic instead"
                )
            known = list(self.server.topic_map.all_topics())
            raise ProtocolError(f"topic: unknown topic {topic}; topics are {known}")

        def joint_states(s: Snapshot) -> bytes:
            body = topics.joint_state_dict(s, world, joints, topics.sim_seconds(s, tick_dt))
            return orjson.dumps({"op": "publish", "topic": topic, "msg": body})

        return joint_states, world, JOINT_STATE_TYPE

    async def write(self) -> None:
        """The socket's one writer: replies first (all of them), then each topic's newest frame."""
        while True:
            await self.ready.wait()
            self.ready.clear()
            while self.replies:
                await self.ws.send_text(self.replies.popleft().decode())
            for entry in list(self.subs.values()):
                sub = entry.hub_sub
                snap, sub.latest = sub.latest, None
                if snap is None:
                    continue
                if entry.changes is not None:  # sent when it changes (and first)
                    now = entry.changes(snap)
                    if now == entry.sent:
                        continue
                    entry.sent = now
                await self.ws.send_text(self.hub.frame(sub, snap).decode())

    def close(self) -> None:
        rosbridge_actions.close(self)
        for entry in self.subs.values():
            self.hub.remove(entry.hub_sub)
        self.subs.clear()


_OPS: dict[str, Callable[[Session, dict[str, Any]], None]] = {
    "advertise": Session.op_advertise,
    "unadvertise": Session.op_unadvertise,
    "publish": Session.op_publish,
    "subscribe": Session.op_subscribe,
    "unsubscribe": Session.op_unsubscribe,
    "call_service": Session.op_call_service,
    "set_level": Session.op_set_level,
    "send_action_goal": rosbridge_actions.send_action_goal,
    "cancel_action_goal": rosbridge_actions.cancel_action_goal,
}
