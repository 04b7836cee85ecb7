"""The wire contract: pydantic models for every HTTP body and WebSocket message.

Numbers are finite floats (NaN/Inf are refused at the edge, before anything is staged).
Joint-state fields follow sensor_msgs/JointState (`name`, `position`, `velocity`, `effort`).
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import (
    BaseModel,
    Field,
)

from service.core.commands.entities import EntityState
from service.core.commands.fields import (
    equal_lengths,
)
from service.core.commands.targets import MAX_BATCH_WORLDS
from service.core.sim.types import JointSpec, Mode

# -- replies ----------------------------------------------------------------------------------


class Info(BaseModel):
    robot: str
    joints: list[JointSpec] = Field(description="the commanded joints, in command order")
    nworld: int
    device: str
    shards: int = Field(description="processes the worlds are split across (CPU cores used)")
    control_hz: float
    physics_dt: float
    substeps: int
    mode: Mode
    tick: int
    sim_time: float = Field(description="tick / control_hz: simulated seconds since start")
    ticks_per_s: float = Field(description="measured over the last second")
    realtime_factor: float = Field(description="simulated seconds per wall second")
    captured: bool = Field(description="the control tick replays a captured graph")


class Flange(BaseModel):
    position: list[float] = Field(description="x y z [m], world frame")
    quaternion: list[float] = Field(description="w x y z")


class WorldState(BaseModel):
    """sensor_msgs/JointState fields plus the target in effect and the flange pose."""

    world: int
    tick: int
    sim_time: float = Field(description="simulated seconds since this world's last reset")
    name: list[str]
    position: list[float]
    velocity: list[float]
    effort: list[float]
    target: list[float]
    flange: Flange
    faults: int = Field(description="times this world was reset for NaN or capacity overflow")
    safety_mode: Literal["NORMAL", "PROTECTIVE_STOP"] = Field(
        description="UR's safety mode: PROTECTIVE_STOP (raised on any world whose commanded "
        "target goes into a fixed obstacle of the scene or whose arm is held at a joint's "
        "torque limit, or by a trigger: `POST /v1/worlds/{w}/trigger_protective_stop`, "
        "ur_rtde's triggerProtectiveStop) until "
        "`POST /v1/worlds/{w}/unlock_protective_stop` or the Dashboard's `unlock protective "
        "stop` (5 s after the stop at the earliest), or a reset; commands that move the arm "
        "are refused (409) meanwhile"
    )
    pending_target: list[float] | None = Field(
        None,
        description="only while paused: the targets as of every accepted command (a paused "
        "service applies them at once, so they equal `target` once applied) [rad]",
    )
    entities: list[EntityState] | None = Field(None, description="only with ?entities=true")


class WorldStates(BaseModel):
    tick: int
    worlds: list[WorldState]


class CommandReply(BaseModel):
    world: int
    target: list[float] = Field(description="the world's 7 targets after this command [rad]")
    clamped: list[str] = Field(description="joints whose target hit a range limit")
    tick: int = Field(description="first tick stepped with this command")


class BatchCommandReply(BaseModel):
    tick: int
    results: list[CommandReply]


class ResetReply(BaseModel):
    worlds: list[int]
    tick: int


class UnlockReply(BaseModel):
    world: int
    tick: int = Field(description="the tick the world was unlocked at")
    safety_mode: Literal["NORMAL"] = Field(description="the world's safety mode after it")


class TriggerReply(BaseModel):
    world: int
    tick: int = Field(
        description="the tick the arm is held from (now, when it was stopped already)"
    )
    safety_mode: Literal["PROTECTIVE_STOP"] = Field(description="the world's safety mode after it")
    why: str = Field(description="the stop's cause: this trigger, or an earlier stop's (kept)")


class SimReply(BaseModel):
    mode: Mode
    tick: int


# -- error replies ----------------------------------------------------------------------------


class ErrorReply(BaseModel):
    """Every 4xx/5xx except 422: what went wrong, in words naming the field and the limit."""

    detail: str


_ERROR_MEANING = {
    400: "the body is not JSON (or not UTF-8)",
    401: "a write (or, with token_reads, a read) without the token, or with a lease's that "
    "has ended",
    403: "a write from a browser page of a foreign origin, or a lease token's on a world (or a "
    "route) not its own",
    404: "no such world (the detail names the ids and the valid range)",
    409: "the request does not fit the current state (e.g. step while not paused, or a "
    "command that moves the arm of a protective-stopped world)",
    413: "the body is over the size limit",
    429: "a lease's commands came faster than its rate (all its connections together)",
    503: "the engine is starting, failed or is rebuilding a shard; or too many clients at once",
}


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """`responses=` for a route: the error statuses it can answer (422 FastAPI adds itself)."""
    return {code: {"model": ErrorReply, "description": _ERROR_MEANING[code]} for code in codes}


def answers(reply: Any, *codes: int) -> dict[str, Any]:
    """A route's answers as one declaration, spread into its decorator (`**answers(...)`): the
    model of its reply (`response_model=`) and the error statuses it can answer besides its
    router's (`responses=`, as `errors`)."""
    return {"response_model": reply, "responses": errors(*codes)}


# Statuses every /v1 route can answer (engine not ready, client cap, token and origin checks).
ANY = (401, 403, 429, 503)
WITH_BODY = (*ANY, 400, 413)


_ERROR_CONTENT = {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorReply"}}}


def fit_openapi(spec: dict[str, Any], nworld: int) -> dict[str, Any]:
    """Tighten the generated OpenAPI to this service's size: a batch lists distinct worlds, so
    it never holds more than `nworld` of them; listing only the lengths that can occur keeps
    the equal-length rule exact and the document small."""
    # Whatever route a surface adds: a JSON body can be unreadable (400) or too large (413), and
    # every /v1 route is behind the token, origin and client-cap checks and needs the engine.
    for path, operations in spec.get("paths", {}).items():
        for op in operations.values():
            if not isinstance(op, dict) or "responses" not in op:
                continue
            codes = [*ANY] if path.startswith("/v1/") else []
            if "requestBody" in op:
                codes += [400, 413]
            for code, response in errors(*codes).items():
                response = {"description": response["description"], "content": _ERROR_CONTENT}
                op["responses"].setdefault(str(code), response)
    batch = spec.get("components", {}).get("schemas", {}).get("BatchTargets")
    if batch is not None:
        most = min(nworld, MAX_BATCH_WORLDS)
        batch["oneOf"] = equal_lengths("worlds", "position", range(1, most + 1))
        for key in ("worlds", "position"):
            batch["properties"][key]["maxItems"] = most
    return spec
