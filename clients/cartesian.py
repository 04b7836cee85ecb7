"""Cartesian calls: the TCP's pose, its offset, pose targets, jogs and moveL, FK and IK.

Poses are UR's p[x, y, z, rx, ry, rz] (position [m], rotation vector [rad]) in the robot's
base frame; the TCP is the flange plus the world's offset (`set_tcp`, flange frame). The calls
are built here once (`*_call`) and run by the mixins the clients inherit: `Calls` (REST, in
`ArmfleetClient`), `AsyncCalls` (`AsyncArmfleetClient`), and `WorldOps` / `AsyncWorldOps`
(the WebSocket ops `jog` and `tcp_target` of `WorldSession` / `AsyncWorldSession`).

    arm.set_tcp(0, [0, 0, 0.2, 0, 0, 0])
    pose = arm.tcp(0)["tcp"]
    arm.jog(0, "z", -0.01, frame="tool")
    done = arm.move_linear(0, [*pose[:2], pose[2] - 0.1, *pose[3:]], speed=0.25, wait=True)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from clients import models
from clients import trajectory as tj
from clients.calls import Call

Pose = Sequence[float]
AXES = ("x", "y", "z", "rx", "ry", "rz")


def _identity(d: Any) -> Any:
    return d


def _six(values: Pose, what: str) -> list[float]:
    out = [float(v) for v in values]
    if len(out) != 6:
        raise ValueError(f"{what} is 6 numbers p[x, y, z, rx, ry, rz], got {len(out)}")
    return out


def jog_body(axis: str, step: float, frame: str = "base") -> dict[str, Any]:
    if axis not in AXES:
        raise ValueError(f"axis is one of {AXES}, got {axis!r}")
    return {"axis": axis, "step": float(step), "frame": frame}


def tcp_call(world: int) -> Call:
    return Call("GET", f"/v1/worlds/{int(world)}/tcp", _identity)


def set_tcp_call(world: int, offset: Pose) -> Call:
    body = {"tcp": _six(offset, "a TCP offset")}
    return Call("PUT", f"/v1/worlds/{int(world)}/tcp_offset", _identity, json=body)


def move_tcp_call(world: int, pose: Pose) -> Call:
    body = {"pose": _six(pose, "a pose")}
    return Call(
        "PUT", f"/v1/worlds/{int(world)}/tcp_target", models.CommandAck.from_json, json=body
    )


def jog_call(world: int, axis: str, step: float, frame: str = "base") -> Call:
    body = jog_body(axis, step, frame)
    return Call("POST", f"/v1/worlds/{int(world)}/jog", models.CommandAck.from_json, json=body)


def move_linear_call(world: int, pose: Pose, speed: float, accel: float) -> Call:
    body = {"pose": _six(pose, "a pose"), "speed": float(speed), "accel": float(accel)}
    path = f"/v1/worlds/{int(world)}/move_linear"
    return Call("POST", path, tj.TrajectoryStarted.from_json, json=body)


def fk_call(world: int, q: Sequence[float]) -> Call:
    body = {"q": [float(v) for v in q]}
    return Call("POST", f"/v1/worlds/{int(world)}/fk", _identity, json=body)


def ik_call(world: int, pose: Pose, q_near: Sequence[float] | None = None) -> Call:
    body: dict[str, Any] = {"pose": _six(pose, "a pose")}
    if q_near is not None:
        body["q_near"] = [float(v) for v in q_near]
    return Call("POST", f"/v1/worlds/{int(world)}/ik", _identity, json=body)


class Calls:
    """The Cartesian methods of `ArmfleetClient` (it runs each `Call` with `self.call`)."""

    def call(self, call: Call) -> Any:
        raise NotImplementedError

    def tcp(self, world: int) -> dict[str, Any]:
        """Flange and TCP poses (actual q), the TCP at the targets, the offset, singularities."""
        return self.call(tcp_call(world))

    def set_tcp(self, world: int, offset: Pose) -> dict[str, Any]:
        """The world's TCP offset from the flange, as UR's set_tcp (moves nothing)."""
        return self.call(set_tcp_call(world, offset))

    def move_tcp(self, world: int, pose: Pose) -> models.CommandAck:
        """Arm targets that put the TCP at `pose` (IK nearest the current targets)."""
        return self.call(move_tcp_call(world, pose))

    def jog(self, world: int, axis: str, step: float, frame: str = "base") -> models.CommandAck:
        """One pendant step along/about x y z rx ry rz of the base or tool frame [m or rad]."""
        return self.call(jog_call(world, axis, step, frame))

    def move_linear(
        self, world: int, pose: Pose, speed: float = 0.25, accel: float = 1.2, wait: bool = False
    ) -> Any:
        """UR's moveL as a trajectory: its TrajectoryStarted, or (wait) its final status."""
        started = self.call(move_linear_call(world, pose, speed, accel))
        if not wait:
            return started
        outcome = tj.OutcomeWait(started.id, None)
        while not outcome.finished(status := self.call(outcome.call())):
            pass
        return status

    def fk(self, world: int, q: Sequence[float]) -> list[float]:
        """The TCP pose (world's offset) of six arm joint angles."""
        return self.call(fk_call(world, q))["pose"]

    def ik(self, world: int, pose: Pose, q_near: Sequence[float] | None = None) -> dict[str, Any]:
        """{ok, q, reason, singular}: the solution nearest q_near (default: the targets)."""
        return self.call(ik_call(world, pose, q_near))


class AsyncCalls:
    """The Cartesian methods of `AsyncArmfleetClient`, awaiting `self.call`."""

    async def call(self, call: Call) -> Any:
        raise NotImplementedError

    async def tcp(self, world: int) -> dict[str, Any]:
        return await self.call(tcp_call(world))

    async def set_tcp(self, world: int, offset: Pose) -> dict[str, Any]:
        return await self.call(set_tcp_call(world, offset))

    async def move_tcp(self, world: int, pose: Pose) -> models.CommandAck:
        return await self.call(move_tcp_call(world, pose))

    async def jog(
        self, world: int, axis: str, step: float, frame: str = "base"
    ) -> models.CommandAck:
        return await self.call(jog_call(world, axis, step, frame))

    async def move_linear(
        self, world: int, pose: Pose, speed: float = 0.25, accel: float = 1.2, wait: bool = False
    ) -> Any:
        started = await self.call(move_linear_call(world, pose, speed, accel))
        if not wait:
            return started
        outcome = tj.OutcomeWait(started.id, None)
        while not outcome.finished(status := await self.call(outcome.call())):
            pass
        return status

    async def fk(self, world: int, q: Sequence[float]) -> list[float]:
        return (await self.call(fk_call(world, q)))["pose"]

    async def ik(
        self, world: int, pose: Pose, q_near: Sequence[float] | None = None
    ) -> dict[str, Any]:
        return await self.call(ik_call(world, pose, q_near))


class WorldOps:
    """`jog` and `tcp_target` over a world's WebSocket (`WorldSession`): acked like Up/Down."""

    def _op(self, op: str, body: dict[str, Any]) -> models.CommandAck:
        return self._command(*self._ids.op(op, body))  # type: ignore[attr-defined]

    def jog(self, axis: str, step: float, frame: str = "base") -> models.CommandAck:
        return self._op("jog", jog_body(axis, step, frame))

    def move_tcp(self, pose: Pose) -> models.CommandAck:
        return self._op("tcp_target", {"pose": _six(pose, "a pose")})


class AsyncWorldOps:
    """`jog` and `tcp_target` over a world's WebSocket (`AsyncWorldSession`)."""

    async def _op(self, op: str, body: dict[str, Any]) -> models.CommandAck:
        return await self._command(*self._ids.op(op, body))  # type: ignore[attr-defined]

    async def jog(self, axis: str, step: float, frame: str = "base") -> models.CommandAck:
        return await self._op("jog", jog_body(axis, step, frame))

    async def move_tcp(self, pose: Pose) -> models.CommandAck:
        return await self._op("tcp_target", {"pose": _six(pose, "a pose")})
