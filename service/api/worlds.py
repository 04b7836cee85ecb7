"""Per-world state and commands: read JointState, press Up/Down, set targets, reset.

Routes only translate HTTP to the control layer and back; validation, staging and the reply
shape live in service/core/commands/control.py and service/core/streams/wire.py, errors are
mapped by the app.
"""

from __future__ import annotations

import asyncio
import dataclasses
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Body, Query
from fastapi.responses import Response

from service.api.answers import command_ack, json_reply, read_fresh
from service.api.deps import CommandWorld, Ctl, Loop, World, moves_arm
from service.core.commands import entities, params, payload, randomize
from service.core.commands.base import HTTP
from service.core.commands.control import Control
from service.core.commands.safety_stop import ProtectiveStop, UnlockProtectiveStop
from service.core.commands.targets import BatchTargets, IncrementRequest, JointTargets
from service.core.commands.world import ResetRequest
from service.core.commands.writes import ManyWrites
from service.core.contract.replies import (
    BatchCommandReply,
    CommandReply,
    ResetReply,
    TriggerReply,
    UnlockReply,
    WorldState,
    WorldStates,
    errors,
)
from service.core.contract.snapshots import WorldRandomization
from service.core.errors import NotFound
from service.core.sim import entities as entity_table
from service.core.sim.loop import SimLoop
from service.core.sim.worlds import WORLDS_PATTERN, parse_worlds
from service.core.streams import wire

# Every route here names worlds, so each can answer 404 for an unknown one.
router = APIRouter(prefix="/v1", tags=["worlds"], responses=errors(404))


# `?entities=true` on a state read: each world's entities too, of the same tick.
WithEntities = Annotated[
    bool,
    Query(description="true: each world's entities (pose and twist) of the same tick too"),
]


@router.get(
    "/worlds/state",
    response_model=WorldStates,
    summary="State of several worlds (default: all), including every command accepted before",
)
async def get_states(
    loop: Loop,
    worlds: Annotated[
        str | None,
        Query(
            description="ids and inclusive ranges, e.g. 0,3,7 or 0-63 (a range may be written "
            "either way round)",
            examples=["0,3,7"],
            pattern=WORLDS_PATTERN,
        ),
    ] = None,
    entities: WithEntities = False,
) -> Response:
    n = loop.batch.nworld
    ids = np.arange(n) if worlds is None else parse_worlds(worlds, n)
    snap, pending = await read_fresh(loop, ids, entities)
    return json_reply(wire.states(snap, ids, loop.spec.names, pending, entities))


@router.get(
    "/worlds/{world}/state",
    response_model=WorldState,
    summary="One world's JointState, target and flange pose, including every command accepted "
    "before",
)
async def get_state(loop: Loop, world: World, entities: WithEntities = False) -> Response:
    snap, pending = await read_fresh(loop, [world], entities)
    pending_row = None if pending is None else pending[0]
    return json_reply(wire.world_state(snap, world, loop.spec.names, pending_row, entities))


@router.post(
    "/worlds/{world}/increments",
    summary="Add to joint targets (the seed's Up/Down buttons); clamps to the joint range",
    **moves_arm(CommandReply),
)
async def increment(control: Ctl, world: CommandWorld, body: IncrementRequest) -> Response:
    field = "deltas" if body.deltas is not None else "joint"
    result = control.increment(world, body.as_mapping(), HTTP, field)
    return command_ack(result)


@router.put(
    "/worlds/{world}/targets",
    summary="Set targets, JointState-shaped; a subset of names keeps the others' targets",
    **moves_arm(CommandReply),
)
async def put_targets(control: Ctl, world: CommandWorld, body: JointTargets) -> Response:
    result = control.command_targets(world, body.name, body.position, HTTP)
    return command_ack(result)


@router.post(
    "/targets",
    summary="Full 7-joint targets for many worlds, applied together at one tick boundary",
    **moves_arm(BatchCommandReply),
)
async def post_targets(control: Ctl, body: BatchTargets) -> Response:
    results = control.set_many(body.worlds, body.position, HTTP)
    return json_reply(
        {"tick": results[0].tick, "results": [wire.command_reply(r) for r in results]}
    )


@router.post(
    "/worlds/{world}/reset",
    response_model=ResetReply,
    summary="Reset one world to home",
)
async def reset_world(control: Ctl, world: CommandWorld) -> ResetReply:
    done = control.reset([world], HTTP)
    return ResetReply(worlds=done.worlds, tick=done.tick)


@router.post(
    "/worlds/{world}/unlock_protective_stop",
    response_model=UnlockReply,
    responses=errors(409),
    summary="Unlock the world's protective stop, as UR's Dashboard `unlock protective stop`: "
    "409 within 5 s of the stop; the arm stays where the stop held it",
)
async def unlock_protective_stop(control: Ctl, world: CommandWorld) -> UnlockReply:
    tick = control.run(UnlockProtectiveStop.create(control, world), HTTP)
    return UnlockReply(world=world, tick=tick, safety_mode="NORMAL")


@router.post(
    "/worlds/{world}/trigger_protective_stop",
    response_model=TriggerReply,
    summary="Protective-stop the world now, as ur_rtde's `triggerProtectiveStop`: the arm is "
    "held where it is until the stop is unlocked (5 s later at the earliest) or the world reset",
)
async def trigger_protective_stop(control: Ctl, world: CommandWorld) -> TriggerReply:
    result = control.run(ProtectiveStop.triggered(control, world, "REST"), HTTP)
    tick = control.loop.tick if result is None else result.tick
    why = control.loop.safety.why(world) or "protective stop"
    return TriggerReply(world=world, tick=tick, safety_mode="PROTECTIVE_STOP", why=why)


@router.post(
    "/reset",
    response_model=ResetReply,
    summary="Reset listed worlds (default: all) to home",
)
async def reset_many(
    control: Ctl, body: Annotated[ResetRequest | None, Body()] = None
) -> ResetReply:
    worlds = body.worlds if body is not None else None
    done = control.reset(worlds, HTTP)
    return ResetReply(worlds=done.worlds, tick=done.tick)


# -- entities: the scene's named free bodies (core/sim/entities.py, core/commands/entities.py)


async def _entities(loop: SimLoop, worlds: list[int]) -> dict[str, Any]:
    """Read-your-writes: wait for the tick every accepted write of `worlds` is in, then read
    the entities on the sim thread between two ticks."""
    await read_fresh(loop, worlds)
    return await asyncio.wrap_future(loop.call(lambda batch: entity_table.read(batch, worlds)))


def _entity(loop: SimLoop, name: str) -> int:
    """The index of the entity a path names; an unknown one is a resource that is not there:
    404 naming the entities there are (in a body, an unknown name is a bad field: 422)."""
    table = entity_table.entity_table(loop.batch.robot.mjm)
    if name not in table.names:
        raise NotFound(f"no entity {name!r}; entities are {list(table.names)}", "name")
    return table.names.index(name)


def _written(control: Control, command: type[ManyWrites[Any]], items: list[Any]) -> Response:
    """Run an entity or parameter write command; the reply is its result's fields (the tick
    the writes take effect at, the worlds written, and what the command adds)."""
    return json_reply(dataclasses.asdict(control.run(command.create(control, items), HTTP)))


@router.get(
    "/worlds/{world}/entities",
    summary="Pose and twist of every entity (named free body) of one world",
)
async def get_entities(loop: Loop, world: World) -> Response:
    got = await _entities(loop, [world])
    return json_reply({"tick": got["tick"], **got["worlds"][0]})


@router.get(
    "/worlds/{world}/entities/{name}",
    summary="Pose and twist of one entity of one world",
)
async def get_entity(loop: Loop, world: World, name: str) -> Response:
    index = _entity(loop, name)
    got = await _entities(loop, [world])
    return json_reply({"tick": got["tick"], "world": world, **got["worlds"][0]["entities"][index]})


@router.put(
    "/worlds/{world}/entities/{name}",
    response_model=entities.EntityAck,
    summary="Set an entity's pose and/or twist in one world, at the next tick boundary",
)
async def put_entity(
    control: Ctl, world: World, name: str, body: entities.EntityValues
) -> Response:
    _entity(control.loop, name)
    item = {**body.model_dump(exclude_none=True), "world": world, "name": name}
    return _written(control, entities.SetEntities, [item])


@router.post(
    "/entities",
    response_model=entities.EntityAck,
    summary="Set entities of many worlds, all at one tick boundary (or none, if one is bad)",
)
async def post_entities(control: Ctl, body: entities.EntityWrites) -> Response:
    return _written(
        control, entities.SetEntities, [w.model_dump(exclude_none=True) for w in body.writes]
    )


# -- per-world physics parameters (service/core/commands/params.py) ------------------------


@router.get("/params", summary="The parameters a world may have of its own: names, units, ranges")
async def get_param_table(loop: Loop) -> Response:
    table = params.param_table(loop.batch.robot.mjm, loop.spec.names)
    return json_reply({"params": [p.describe() for p in table.values()]})


@router.get("/worlds/{world}/params", summary="One world's physics parameters")
async def get_params(loop: Loop, world: World) -> Response:
    await read_fresh(loop, [world])
    got = await asyncio.wrap_future(loop.call(lambda batch: params.read(batch, [world])))
    return json_reply({"tick": got["tick"], **got["worlds"][0]})


@router.put(
    "/worlds/{world}/params",
    response_model=params.ParamsAck,
    summary="Give one world its own physics parameters, from the next tick boundary",
)
async def put_params(control: Ctl, world: World, body: params.ParamValues) -> Response:
    return _written(control, params.SetParams, [{"world": world, "params": body.params}])


@router.put(
    "/worlds/{world}/payload",
    response_model=params.ParamsAck,
    summary="Set the payload the arm carries (mass, centre of gravity), as UR's set_payload",
)
async def put_payload(control: Ctl, world: World, body: payload.PayloadValues) -> Response:
    return _written(control, payload.SetPayload, [{"world": world, **body.model_dump()}])


@router.post(
    "/params",
    response_model=params.ParamsAck,
    summary="Physics parameters of many worlds, all from one tick boundary (or none)",
)
async def post_params(control: Ctl, body: params.ParamWrites) -> Response:
    return _written(control, params.SetParams, [w.model_dump() for w in body.writes])


@router.get(
    "/worlds/{world}/randomization",
    response_model=WorldRandomization,
    summary="One world's last randomisation (seed and spec), as its state holds it now",
)
async def get_randomization(loop: Loop, world: World) -> WorldRandomization:
    snap, _ = await read_fresh(loop, [world])  # includes every randomisation accepted before
    last = loop.randomizations.at(snap.tick).get(world)
    return WorldRandomization(
        world=world,
        tick=snap.tick,
        randomized_at=None if last is None else last.tick,
        seed=None if last is None else last.seed,
        spec=None if last is None else dict(last.spec),
    )


@router.post(
    "/randomize",
    response_model=randomize.RandomizeAck,
    summary="Reset worlds (default: all) with entity poses and parameters drawn with a seed",
)
async def post_randomize(control: Ctl, body: randomize.RandomizeRequest) -> Response:
    command = randomize.Randomize.create(control, body.worlds, body.seed, body.spec)
    done = control.run(command, HTTP)
    return json_reply(
        {"tick": done.tick, "worlds": done.worlds, "seed": body.seed, "spec": body.spec}
    )
