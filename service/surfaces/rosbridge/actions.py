"""rosbridge v2 actions (rosbridge_suite 2.x): `send_action_goal`, `cancel_action_goal`, and
the `action_feedback` / `action_result` frames that answer them, for the UR driver's actions.

As in rosbridge_suite's SendActionGoal capability: the goal is `args` (the action's Goal
message), the request's `id` names the goal from then on (`cancel_action_goal` sends the same
`id`), feedback frames come only when the request asked for them (`"feedback": true`), and the
result frame carries the result message in `values`, the final GoalStatus in `status` and
`result: true`. A goal that cannot run (unknown action, wrong type, invalid goal, no right to
command) gets `result: false` with the reason in `values` and status UNKNOWN, which roslibpy
hands to its errback and roslib.js to its failed callback; nothing moves.

The goals run in service/surfaces/rosbridge/goals.py; its callbacks come from
other threads, so frames are queued onto the socket's event loop.
"""

from __future__ import annotations

import asyncio
from typing import Any

from clients import ros_rules
from clients.ros_rules import GoalRejected, Status
from service.core.errors import ArmfleetError
from service.surfaces.rosbridge.base import ROSBRIDGE, ProtocolError, topic_name
from service.surfaces.rosbridge.goal_msgs import action_names
from service.surfaces.rosbridge.goals import Goal, runner_of


def _type_matches(given: Any, kind: str) -> bool:
    """rosbridge accepts `pkg/action/Type` and `pkg/Type`."""
    pkg, _, name = kind.partition("/action/")
    return given in (kind, f"{pkg}/{name}")


class _Goals:
    """One session's goals by request id, and how to reach the session from other threads."""

    def __init__(self, session: Any) -> None:
        self.session = session
        self.loop = asyncio.get_running_loop()
        self.by_id: dict[Any, Goal] = {}
        self.closed = False

    def send(self, frame: dict[str, Any]) -> None:
        """Queue a frame from any thread (dropped once the socket has closed)."""
        if not self.closed:
            self.loop.call_soon_threadsafe(self._send, frame)

    def _send(self, frame: dict[str, Any]) -> None:
        if not self.closed:
            self.session._reply(frame)


def _goals(session: Any) -> _Goals:
    goals = getattr(session, "action_goals", None)
    if goals is None:
        goals = session.action_goals = _Goals(session)
    return goals


def _failure(session: Any, msg_id: Any, action: Any, why: str) -> None:
    frame = {"op": "action_result", "action": action, "values": why, "status": 0, "result": False}
    if msg_id is not None:
        frame["id"] = msg_id
    session.server.bad.report("rejected_goal", str(action), why)
    session._reply(frame)


def send_action_goal(session: Any, msg: dict[str, Any]) -> None:
    """Start a goal; its feedback and result frames follow on this socket."""
    msg_id, action = msg.get("id"), msg.get("action")
    try:
        name = topic_name(action, "action")
        known = action_names(session.server.topic_map.namespaces())
        if name not in known:
            raise GoalRejected(f"action: unknown action {name}; actions are {sorted(known)}")
        world, kind = known[name]
        if not _type_matches(msg.get("action_type"), kind):
            raise GoalRejected(f"action_type: {name} is a {kind}, not {msg.get('action_type')!r}")
        if not session.grant.command:
            raise GoalRejected(session.grant.reason)
        verdict = session.limiter.take()
        if verdict != "ok":
            session.over_rate = verdict == "close"
            raise GoalRejected(session.limiter.detail)
        goals = _goals(session)
        if msg_id in goals.by_id and not goals.by_id[msg_id].status.terminal:
            raise GoalRejected(f"id: a goal with id {msg_id!r} is still running")
        args = msg.get("args") or {}
        want_feedback = bool(msg.get("feedback", False))

        def on_feedback(goal: Goal, values: dict[str, Any]) -> None:
            if want_feedback:
                frame = {"op": "action_feedback", "action": action, "values": values}
                goals.send({**frame, "id": msg_id} if msg_id is not None else frame)

        def on_done(goal: Goal) -> None:
            frame = {
                "op": "action_result",
                "action": action,
                "values": goal.result,
                "status": int(goal.status),
                "result": True,
            }
            goals.send({**frame, "id": msg_id} if msg_id is not None else frame)

        runner = runner_of(session.ctx)
        goal = runner.submit(
            name, kind, world, args, ROSBRIDGE, on_feedback, on_done, session.control
        )
        goal.key = msg_id
        goals.by_id[msg_id] = goal
    except (GoalRejected, ProtocolError, ArmfleetError) as exc:  # Forbidden: not its world
        _failure(session, msg_id, action, str(exc))


def cancel_action_goal(session: Any, msg: dict[str, Any]) -> None:
    """Cancel the goal started with the same `id`; its result frame reports CANCELED."""
    goals = _goals(session)
    goal = goals.by_id.get(msg.get("id"))
    if goal is None:
        raise ProtocolError(f"id: no goal of this client has id {msg.get('id')!r}")
    if goal.status != Status.CANCELED:
        runner_of(session.ctx).cancel(goal, ROSBRIDGE)


def cancel_all(session: Any, action: str) -> dict[str, Any]:
    """`call_service <action>/_action/cancel_goal` (roslib.js's cancelAllGoals): every running
    goal of the action is cancelled, as a CancelGoal request with an empty goal_info asks."""
    if action not in action_names(session.server.topic_map.namespaces()):
        raise ProtocolError(f"service: no action {action}")
    canceling = runner_of(session.ctx).cancel_all(action, ROSBRIDGE)
    infos = []
    for goal in canceling:
        key = goal.key if isinstance(goal.key, bytes) else bytes(16)
        sec, nanosec = ros_rules.stamp(goal.accepted_at)
        infos.append({"goal_id": {"uuid": list(key)}, "stamp": {"sec": sec, "nanosec": nanosec}})
    return {"return_code": 0 if infos else 1, "goals_canceling": infos}


def close(session: Any) -> None:
    """The socket closed: its goals run on, their frames go nowhere."""
    goals = getattr(session, "action_goals", None)
    if goals is not None:
        goals.closed = True
