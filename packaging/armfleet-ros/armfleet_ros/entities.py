"""The scene's free bodies ("entities") for simulation_interfaces, through armfleet's entity API.

armfleet's entity (GET/PUT /v1/worlds/{w}/entities/{name}) is a pose (position, orientation
w x y z) and a twist whose linear velocity is in the world frame and whose angular velocity is in
the body's frame. simulation_interfaces' EntityState carries both velocities in the world frame
(header.frame_id "world"), as Gazebo and Isaac Sim do: this module turns one into the other, the
angular velocity through the body's orientation (the written one, on a set). A set writes the
whole EntityState (pose and twist, as the message always has both) at armfleet's next tick
boundary; armfleet validates it and its refusal text is the reply's error_message.
Acceleration is not measured: zeros.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from simulation_interfaces.msg import Result

from clients import ros_rules
from clients.errors import ArmfleetError, Conflict


def _rotation(q_wxyz: Sequence[float]) -> list[list[float]]:
    """The rotation matrix of a quaternion (normalised here; the identity for a zero one)."""
    n = math.sqrt(sum(v * v for v in q_wxyz))
    if n == 0.0:
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    w, x, y, z = (v / n for v in q_wxyz)
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def _apply(r: list[list[float]], v: Sequence[float], transpose: bool = False) -> list[float]:
    if transpose:
        return [sum(r[j][i] * v[j] for j in range(3)) for i in range(3)]
    return [sum(r[i][j] * v[j] for j in range(3)) for i in range(3)]


def fill(state: Any, entity: dict[str, Any], tick: int, tick_dt: float) -> None:
    """An EntityState from one armfleet entity reply (world-frame twist, stamped at `tick`)."""
    state.header.frame_id = "world"
    state.header.stamp.sec, state.header.stamp.nanosec = ros_rules.stamp(tick * tick_dt)
    q = [float(v) for v in entity["orientation"]]
    p, o = state.pose.position, state.pose.orientation
    p.x, p.y, p.z = (float(v) for v in entity["position"])
    o.w, o.x, o.y, o.z = q
    lin, ang = state.twist.linear, state.twist.angular
    lin.x, lin.y, lin.z = (float(v) for v in entity["linear"])
    ang.x, ang.y, ang.z = _apply(_rotation(q), [float(v) for v in entity["angular"]])


def _vector(msg: Any, field: str, keys: str = "xyz") -> list[float]:
    values = [float(getattr(msg, k)) for k in keys]
    for k, v in zip(keys, values, strict=True):
        if not math.isfinite(v):
            raise ValueError(f"{field}.{k} is {v} (must be finite)")
    return values


def values(state: Any) -> dict[str, list[float]]:
    """An EntityState as armfleet's entity body (angular velocity into the body's frame)."""
    pose, twist = state.pose, state.twist
    x, y, z, w = _vector(pose.orientation, "state.pose.orientation", "xyzw")
    quat = [w, x, y, z]
    angular = _vector(twist.angular, "state.twist.angular")
    return {
        "position": _vector(pose.position, "state.pose.position"),
        "orientation": quat,
        "linear": _vector(twist.linear, "state.twist.linear"),
        "angular": _apply(_rotation(quat), angular, transpose=True),
    }


def set_state(http: Any, world: int, names: Sequence[str], req: Any, res: Any) -> Any:
    """SetEntityState on armfleet: OK once accepted (in effect from its next tick); NOT_FOUND
    for a name that is no free body of the scene; INCORRECT_STATE where armfleet's mode
    refuses it; OPERATION_FAILED for a value armfleet refuses (its text names the field and
    the limit). A refused set changes nothing."""
    try:
        body = values(req.state)
        http.set_entity(world, req.entity, **body)
    except ValueError as exc:
        return result(res, Result.RESULT_OPERATION_FAILED, str(exc))
    except Conflict as exc:
        return result(res, Result.RESULT_INCORRECT_STATE, str(exc))
    except ArmfleetError as exc:
        code = Result.RESULT_OPERATION_FAILED if req.entity in names else Result.RESULT_NOT_FOUND
        return result(res, code, str(exc))
    return result(res, Result.RESULT_OK)


def result(msg: Any, code: int, text: str = "") -> Any:
    msg.result.result = code
    msg.result.error_message = text
    return msg
