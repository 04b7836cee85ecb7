"""Cartesian routes: a world's flange and TCP poses, its TCP offset, TCP targets, jogs, moveL,
and forward/inverse kinematics with the world's TCP.

Poses are UR's p[x, y, z, rx, ry, rz] in the robot's base frame (service.core.kinematics says
the frames); commands are service.core.commands.cartesian / tcp, run through Control like every
other; a pose no configuration reaches is a 422 naming the field.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter
from fastapi.responses import Response
from pydantic import BaseModel, Field

from service.api.answers import command_ack, json_reply, read_fresh
from service.api.deps import CommandWorld, Ctl, Loop, World, moves_arm
from service.core.commands import cartesian, tcp
from service.core.commands.base import HTTP
from service.core.commands.fields import FiniteFloat, Strict, example_config
from service.core.commands.trajectory.schemas import StartedReply
from service.core.contract.replies import CommandReply, errors
from service.core.kinematics.pose import matrix_to_pose, matrix_to_quat
from service.core.kinematics.tools import tools_of
from service.core.kinematics.ur import Singularity
from service.core.sim import safety

router = APIRouter(prefix="/v1", tags=["cartesian"], responses=errors(404))

Six = Annotated[list[FiniteFloat], Field(min_length=6, max_length=6)]


class TcpReply(BaseModel):
    world: int
    tick: int
    tcp_offset: list[float] = Field(description="the TCP offset from the flange (set_tcp)")
    flange: list[float] = Field(description="the flange pose p[...] in the base frame, actual q")
    tcp: list[float] = Field(description="the TCP pose in the base frame at the actual q")
    target_tcp: list[float] = Field(description="the TCP pose at the targets")
    singular: list[str] = Field(description="singularities of the actual q: wrist, elbow, shoulder")
    safety_mode: Literal["NORMAL", "PROTECTIVE_STOP"] = Field(
        description="the world's safety mode as of now, as in its state (PROTECTIVE_STOP: "
        "commands that move the arm, TCP targets and jogs included, are refused with 409)"
    )
    base_in_world: dict[str, list[float]] = Field(
        description="the robot's base frame in MuJoCo's world frame: position, quaternion w x y z"
    )


class JointAngles(Strict):
    q: Six = Field(description="the six arm joints [rad]")

    model_config = example_config({"q": [-1.5708, -1.5708, 1.5708, -1.5708, -1.5708, 0]})


class IkRequest(Strict):
    pose: list[FiniteFloat] = cartesian.POSE
    q_near: Six | None = Field(default=None, description="default: the world's arm targets")

    model_config = example_config({"pose": [-0.69, -0.17, 0.5, 2.22, 2.22, 0]})


@router.get(
    "/worlds/{world}/tcp",
    response_model=TcpReply,
    summary="The world's flange and TCP poses in the robot's base frame (UR's p[...]), "
    "including every command accepted before",
)
async def get_tcp(loop: Loop, world: World) -> Response:
    snap, pending = await read_fresh(loop, [world])
    tools = tools_of(loop)
    kin, offset = tools.kin, tools.get(world)
    q = snap.position[world, :6][None].astype(np.float64)
    target = (snap.target[world] if pending is None else pending[0])[:6][None]
    base = kin.base_in_world
    return json_reply(
        {
            "world": world,
            "tick": snap.tick,
            "tcp_offset": offset.tolist(),
            "flange": kin.fk(q)[0].tolist(),
            "tcp": kin.fk(q, offset[None])[0].tolist(),
            "target_tcp": kin.fk(target, offset[None])[0].tolist(),
            "singular": Singularity.names(int(kin.singularity(q)[0])),
            "safety_mode": safety.names(snap.safety[[world]])[0]
            if snap.safety is not None
            else "NORMAL",
            "base_in_world": {
                "position": base[:3, 3].tolist(),
                "quaternion": matrix_to_quat(base[:3, :3]).tolist(),
            },
        }
    )


@router.put(
    "/worlds/{world}/tcp_offset",
    summary="Set the world's TCP offset from the flange, as UR's set_tcp (moves nothing)",
)
async def put_tcp_offset(control: Ctl, world: CommandWorld, body: tcp.TcpOffset) -> Response:
    done = control.run(tcp.SetTcp.create(control, world, body.tcp), HTTP)
    return json_reply({"world": done.world, "tick": done.tick, "tcp": done.tcp})


@router.put(
    "/worlds/{world}/tcp_target",
    summary="Set the arm's targets so that the TCP reaches a pose (IK nearest the current "
    "targets); 422 when no configuration reaches it",
    **moves_arm(CommandReply),
)
async def put_tcp_target(control: Ctl, world: CommandWorld, body: cartesian.TcpPose) -> Response:
    result = control.run(cartesian.MoveTcp.create(control, world, body.pose), HTTP)
    return command_ack(result)


@router.post(
    "/worlds/{world}/jog",
    summary="One pendant jog step: ±x/y/z [m] or ±rx/ry/rz [rad] in the base or tool frame",
    **moves_arm(CommandReply),
)
async def post_jog(control: Ctl, world: CommandWorld, body: cartesian.JogStep) -> Response:
    command = cartesian.Jog.create(control, world, body.axis, body.step, body.frame)
    return command_ack(control.run(command, HTTP))


@router.post(
    "/worlds/{world}/move_linear",
    summary="Move the TCP on a straight line (UR's moveL) as a trajectory: its id and ticks "
    "(GET /v1/worlds/{w}/trajectory watches it)",
    **moves_arm(StartedReply),
)
async def post_move_linear(
    control: Ctl, world: CommandWorld, body: cartesian.LinearMove
) -> Response:
    command = cartesian.MoveLinear.line(control, world, body.pose, body.speed, body.accel)
    return json_reply(control.run(command, HTTP)[0].as_json())


@router.post("/worlds/{world}/fk", summary="The TCP pose of arm joint angles, with the world's TCP")
async def post_fk(loop: Loop, world: World, body: JointAngles) -> Response:
    tools = tools_of(loop)
    t = tools.kin.tcp(np.array([body.q]), tools.get(world)[None])
    return json_reply({"world": world, "pose": matrix_to_pose(t)[0].tolist()})


@router.post(
    "/worlds/{world}/ik",
    summary="Arm joint angles for a TCP pose (the closed-form solution nearest q_near), with "
    "the world's TCP; `ok` false and `reason` when none",
)
async def post_ik(loop: Loop, world: World, body: IkRequest) -> Response:
    tools = tools_of(loop)
    pose = tcp.pose_values(body.pose, "pose", tcp.POSE_REACH)
    near = body.q_near
    q_near = loop.commands.pending_targets(world)[:6] if near is None else np.array(near)
    got = tools.kin.ik(pose[None], q_near[None], tools.get(world)[None])
    return json_reply(
        {
            "world": world,
            "ok": bool(got.ok[0]),
            "q": got.q[0].tolist() if got.ok[0] else None,
            "reason": got.why(0),
            "singular": Singularity.names(int(got.singular[0])),
        }
    )
