"""ROS 2 action servers on DDS, the way rmw_cyclonedds_cpp lays them out.

An action `/ns/ctrl/act` is, per ROS 2's action design, three services and two topics:
`rq/ns/ctrl/act/_action/send_goalRequest` + `rr/.../send_goalReply`, the same for
`cancel_goal` and `get_result`, `rt/.../_action/feedback` and `rt/.../_action/status`
(action_msgs/GoalStatusArray, transient-local). Following rmw_cyclonedds_cpp, every request and
reply starts with the client's guid and a sequence number (echoed in the reply), the request
reader and reply writer carry `serviceid=<id>;` in their USER_DATA (how a client sees that the
server is there), and a reply waits up to 100 ms for the client's reply reader to be matched
(a fresh client's reader may not be yet).

The goals themselves run in service/ros/goals.py (shared with rosbridge); this module only
speaks the wire: requests in, replies, feedback and status out. `get_result` is answered when
the goal ends (at once if it already has).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import fields, is_dataclass
from typing import Any

from service.surfaces.ros import msgs_action as m
from service.surfaces.ros.goal_msgs import FJT_TYPE, GRIPPER_TYPE, GoalRejected, Status
from service.surfaces.ros.goals import Goal, GoalRunner
from service.surfaces.ros.msgs import Time
from service.surfaces.ros.topics import ROS2, BadMessageCounter, stamp

log = logging.getLogger("armfleet.ros2")

_TYPES = {FJT_TYPE: m.FOLLOW_JOINT_TRAJECTORY, GRIPPER_TYPE: m.GRIPPER_COMMAND}
_KEEP_FINISHED = 64  # ended goals kept for get_result and the status list, per action
_CLIENT_WAIT_S = 0.1  # rmw_cyclonedds_cpp waits as long for a client's reply reader
CANCEL_OK, CANCEL_REJECTED, CANCEL_UNKNOWN_GOAL, CANCEL_TERMINATED = 0, 1, 2, 3


def to_plain(value: Any) -> Any:
    """An IdlStruct sample → the ROS message in JSON shape (what goals.py reads)."""
    if is_dataclass(value):
        return {f.name: to_plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, list | tuple):
        return [to_plain(v) for v in value]
    return value


def from_plain(cls: type, value: dict[str, Any]) -> Any:
    """JSON-shaped message → IdlStruct of `cls` (nested structs and lists of numbers/strings)."""
    out = cls()
    for key, v in value.items():
        current = getattr(out, key)
        setattr(out, key, from_plain(type(current), v) if is_dataclass(current) else v)
    return out


def _time(seconds: float) -> Time:
    sec, nanosec = stamp(seconds)
    return Time(sec=sec, nanosec=nanosec)


def _user_data(endpoint: Any) -> bytes:
    from cyclonedds.qos import Policy

    try:
        return bytes(endpoint.qos[Policy.Userdata].data)
    except (KeyError, AttributeError):
        return b""


class _Service:
    """One service of an action: a request reader and a reply writer with our serviceid."""

    def __init__(self, make: Callable[..., Any], name: str, req: type, rep: type, sid: bytes):
        from cyclonedds.qos import Policy

        user = Policy.Userdata(b"serviceid=" + sid + b";")
        self.name = name
        self.reader = make("reader", f"rq{name}Request", req, user)
        self.writer = make("writer", f"rr{name}Reply", rep, user)

    def reply(self, request_info: Any, response: Any) -> None:
        """Write `response` once the requesting client's reply reader is matched (≤ 100 ms)."""
        client = b""
        try:
            pub = self.reader.get_matched_publication_data(request_info.publication_handle)
            data = _user_data(pub)
            if data.startswith(b"clientid="):
                client = data[len(b"clientid=") :]
        except Exception:
            pass  # a client without an id: reply at once, as rmw_cyclonedds_cpp does
        deadline = time.monotonic() + _CLIENT_WAIT_S
        while client and time.monotonic() < deadline:
            handles = self.writer.get_matched_subscriptions()
            if any(
                _user_data(self.writer.get_matched_subscription_data(h)) == b"clientid=" + client
                for h in handles
            ):
                break
            time.sleep(0.005)
        self.writer.write(response)


class ActionServerDds:
    """One action of one world on DDS (see the module docstring)."""

    def __init__(
        self,
        make: Callable[..., Any],
        service_id: Callable[[], bytes],
        name: str,
        kind: str,
        world: int,
        runner: GoalRunner,
        bad: BadMessageCounter,
    ) -> None:
        self.name, self.kind, self.world = name, kind, world
        self._runner, self._bad = runner, bad
        t = self._t = _TYPES[kind]
        base = f"{name}/_action"
        self.send_goal = _Service(
            make, f"{base}/send_goal", t.send_goal_request, t.send_goal_response, service_id()
        )
        self.cancel_goal = _Service(
            make,
            f"{base}/cancel_goal",
            m.CancelGoalRequest,
            m.CancelGoalResponse,
            service_id(),
        )
        self.get_result = _Service(
            make, f"{base}/get_result", t.get_result_request, t.get_result_response, service_id()
        )
        self.feedback = make("writer", f"rt{base}/feedback", t.feedback_message, None)
        self.status_writer = make("latched", f"rt{base}/status", m.GoalStatusArray, None)
        self._lock = threading.Lock()
        self._goals: OrderedDict[bytes, Goal] = OrderedDict()
        self._waiting: dict[bytes, list[tuple[Any, int, int]]] = {}  # get_result requests
        self._publish_status()

    @property
    def services(self) -> list[_Service]:
        return [self.send_goal, self.cancel_goal, self.get_result]

    def inputs(self) -> list[Callable[[], bool]]:
        """What the reader thread calls to serve each request reader (True: took something)."""
        return [
            self._serve(self.send_goal, self._on_send_goal),
            self._serve(self.cancel_goal, self._on_cancel),
            self._serve(self.get_result, self._on_get_result),
        ]

    def _serve(self, service: _Service, handle: Callable[[Any, Any], None]) -> Callable[[], bool]:
        def serve_one() -> bool:
            try:
                samples = service.reader.take(N=16)
            except Exception as exc:
                self._bad.report("malformed", service.name, f"undecodable request ({exc})")
                return True
            for sample in samples:
                if not hasattr(sample, "client_guid"):
                    continue  # a dispose notice
                try:
                    handle(sample, sample.sample_info)
                except Exception:
                    log.exception("ROS 2 request on %s failed", service.name)
            return bool(samples)

        return serve_one

    # -- requests ------------------------------------------------------------------------------

    def _on_send_goal(self, req: Any, info: Any) -> None:
        rep = self._t.send_goal_response
        key = bytes(req.goal_id.uuid)
        accepted = False
        with self._lock:
            known = key in self._goals
        if known:
            self._bad.report("rejected_goal", self.name, "a goal with this id was sent before")
        else:
            try:
                goal = self._runner.submit(
                    self.name,
                    self.kind,
                    self.world,
                    to_plain(req.goal),
                    ROS2,
                    self._on_feedback,
                    self._on_done,
                )
            except GoalRejected as exc:
                self._bad.report("rejected_goal", self.name, str(exc))
            else:
                goal.key = key
                with self._lock:
                    self._goals[key] = goal
                    self._trim()
                accepted = True
        at = _time(self._runner.now())
        self.send_goal.reply(info, rep(req.client_guid, req.sequence_number, accepted, at))
        if accepted:
            self._publish_status()

    def _on_cancel(self, req: Any, info: Any) -> None:
        key = bytes(req.goal_info.goal_id.uuid)
        before = req.goal_info.stamp.sec + req.goal_info.stamp.nanosec * 1e-9
        everything = not any(key) and before == 0
        with self._lock:
            goals = list(self._goals.values())
        chosen = [
            g
            for g in goals
            if everything or g.key == key or (before > 0 and g.accepted_at <= before)
        ]
        canceling = [g for g in chosen if self._runner.cancel(g, ROS2)]
        if canceling:
            code = CANCEL_OK
        elif any(key) and not any(g.key == key for g in goals):
            code = CANCEL_UNKNOWN_GOAL
        elif chosen:
            code = CANCEL_TERMINATED
        else:
            code = CANCEL_REJECTED
        infos = [m.GoalInfo(m.UUID(list(g.key)), _time(g.accepted_at)) for g in canceling]
        response = m.CancelGoalResponse(req.client_guid, req.sequence_number, code, infos)
        self.cancel_goal.reply(info, response)
        if canceling:
            self._publish_status()

    def _on_get_result(self, req: Any, info: Any) -> None:
        key = bytes(req.goal_id.uuid)
        with self._lock:
            goal = self._goals.get(key)
            if goal is not None and not goal.status.terminal:
                self._waiting.setdefault(key, []).append(
                    (info, req.client_guid, req.sequence_number)
                )
                return
        self._send_result(goal, [(info, req.client_guid, req.sequence_number)])

    def _send_result(self, goal: Goal | None, requests: list[tuple[Any, int, int]]) -> None:
        res_rep = self._t.get_result_response
        status = Status.UNKNOWN if goal is None else goal.status
        result = from_plain(self._t.result, goal.result if goal is not None else {})
        for info, guid, seq in requests:
            self.get_result.reply(info, res_rep(guid, seq, int(status), result))

    # -- the runner's callbacks ---------------------------------------------------------------

    def _on_feedback(self, goal: Goal, feedback: dict[str, Any]) -> None:
        uuid = m.UUID(list(goal.key))
        self.feedback.write(self._t.feedback_message(uuid, from_plain(self._t.feedback, feedback)))

    def _on_done(self, goal: Goal) -> None:
        with self._lock:
            waiting = self._waiting.pop(goal.key, [])
        self._publish_status()
        self._send_result(goal, waiting)

    def _publish_status(self) -> None:
        with self._lock:
            goals = list(self._goals.values())
        self.status_writer.write(
            m.GoalStatusArray(
                [
                    m.GoalStatus(
                        m.GoalInfo(m.UUID(list(g.key)), _time(g.accepted_at)),
                        int(g.status),
                    )
                    for g in goals
                ]
            )
        )

    def _trim(self) -> None:
        """Forget the oldest ended goals beyond _KEEP_FINISHED (lock held)."""
        ended = [k for k, g in self._goals.items() if g.status.terminal]
        for key in ended[: max(0, len(ended) - _KEEP_FINISHED)]:
            del self._goals[key]
