"""simulation_interfaces' entity services on the rosbridge socket: SetEntityState and
GetEntityState, as Gazebo and Isaac Sim serve them, per world.

`/set_entity_state` and `/get_entity_state` are world 0's; `/world_N/set_entity_state` world
N's. Arguments and replies follow simulation_interfaces/srv (`entity`: the entity's name;
`state`: an EntityState of `pose` (position, orientation x y z w) and `twist` (linear and
angular velocity, both in the world frame, `header.frame_id` "world")). A set goes through the
control layer as the `set_entity` command (validated by its rules, applied at one tick
boundary); a get waits for the tick of the world's last accepted command and reads the engine
between two ticks, replying when the read is done, without holding up the socket's other work.
`result.result` is simulation_interfaces/Result's code: 1 OK, 2 not found (no such entity),
4 failed (a value refused: `error_message` names the field and the limit). A get's
`acceleration` is not measured: it is all zeros.
"""

from __future__ import annotations

import asyncio
import re
from collections.abc import Callable
from typing import Any

import numpy as np

from clients import ros_rules
from service.core.commands import entities
from service.core.errors import ArmfleetError, BadCommand
from service.core.sim import entities as entity_table
from service.surfaces.rosbridge import topics
from service.surfaces.rosbridge.base import ROSBRIDGE

OK, NOT_FOUND, FAILED = 1, 2, 4
_ZERO = {"x": 0.0, "y": 0.0, "z": 0.0}
_NAME = re.compile(r"^(?:/world_(\d+))?/(set|get)_entity_state$")

Reply = Callable[[dict[str, Any]], None]


def match(name: str, nworld: int) -> tuple[str, int] | None:
    """("set" or "get", world) for a service name of this module, else None."""
    m = _NAME.match(name)
    if m is None or (m.group(1) is not None and int(m.group(1)) >= nworld):
        return None
    return m.group(2), int(m.group(1) or 0)


def _rotation(q_wxyz: np.ndarray) -> np.ndarray:
    w, x, y, z = q_wxyz / np.linalg.norm(q_wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _xyz(v: Any, field: str, keys: str = "xyz") -> list[Any]:
    if not isinstance(v, dict):
        raise BadCommand(field, f"must be an object with {', '.join(keys)}")
    return [v.get(k, 0.0) for k in keys]


def _result(code: int, message: str = "") -> dict[str, Any]:
    return {"result": {"result": code, "error_message": message}}


def set_state(session: Any, world: int, args: Any) -> dict[str, Any]:
    """SetEntityState: the entity's pose and/or twist, from the next tick boundary (while
    paused: at once, as the loop applies every write made while time stands still)."""
    try:
        if not session.grant.command:
            raise BadCommand("grant", session.grant.reason)
        if not isinstance(args, dict) or not isinstance(args.get("state"), dict):
            raise BadCommand("state", "SetEntityState takes {entity, state: {pose, twist}}")
        state, item = args["state"], {"world": world, "name": args.get("entity")}
        table = entity_table.entity_table(session.loop.batch.robot.mjm)
        table.index(item["name"], "entity")
        quat = None
        if (pose := state.get("pose")) is not None:
            item["position"] = _xyz(pose.get("position", {}), "state.pose.position")
            x, y, z, w = _xyz(pose.get("orientation", {"w": 1.0}), "orientation", "xyzw")
            item["orientation"] = quat = [w, x, y, z]
        if (twist := state.get("twist")) is not None:
            item["linear"] = _xyz(twist.get("linear", {}), "state.twist.linear")
            angular = _xyz(twist.get("angular", {}), "state.twist.angular")
            if quat is None:  # the world frame's angular velocity into the body's, as now
                b = int(table.body[table.index(item["name"])])
                quat = session.loop.latest.body_quat[world, b].astype(float)
            if all(isinstance(v, int | float) for v in (*angular, *quat)):
                angular = (_rotation(np.array(quat, dtype=float)).T @ angular).tolist()
            item["angular"] = angular
        session.control.run(entities.SetEntities.create(session.control, [item]), ROSBRIDGE)
    except BadCommand as exc:
        code = NOT_FOUND if exc.field == "entity" else FAILED
        return _result(code, str(exc))
    except ArmfleetError as exc:
        return _result(FAILED, str(exc))
    return _result(OK)


def get_state(session: Any, world: int, args: Any, reply: Reply) -> None:
    """GetEntityState: `reply(values)` once the engine was read (from the event loop)."""
    name = args.get("entity") if isinstance(args, dict) else None
    table = entity_table.entity_table(session.loop.batch.robot.mjm)
    try:
        index = table.index(name, "entity")
    except BadCommand as exc:
        reply(_result(NOT_FOUND, str(exc)))
        return
    aio = asyncio.get_running_loop()
    loop = session.loop

    def done(fut: Any) -> None:
        try:
            got = fut.result()
        except Exception as exc:  # the engine could not be read: say so, keep the socket
            aio.call_soon_threadsafe(reply, _result(FAILED, f"{type(exc).__name__}: {exc}"))
            return
        e = got["worlds"][0]["entities"][index]
        q = e["orientation"]
        angular = (_rotation(np.array(q)) @ np.array(e["angular"])).tolist()
        sec, nanosec = ros_rules.stamp(topics.sim_seconds(loop.latest, session.tick_dt))
        stamp = {"sec": sec, "nanosec": nanosec}
        state = {
            "header": {"stamp": stamp, "frame_id": "world"},
            "pose": {
                "position": dict(zip("xyz", e["position"], strict=True)),
                "orientation": {"x": q[1], "y": q[2], "z": q[3], "w": q[0]},
            },
            "twist": {
                "linear": dict(zip("xyz", e["linear"], strict=True)),
                "angular": dict(zip("xyz", angular, strict=True)),
            },
            "acceleration": {"linear": _ZERO, "angular": _ZERO},
        }
        aio.call_soon_threadsafe(reply, {**_result(OK), "state": state})

    def fresh(_: Any) -> None:  # read-your-writes: the tick of its last command, then the read
        loop.call(lambda batch: entity_table.read(batch, [world])).add_done_callback(done)

    loop.fresh_snapshot([world]).add_done_callback(fresh)
