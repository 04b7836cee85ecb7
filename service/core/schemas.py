"""The wire contract: pydantic models for every HTTP body and WebSocket message.

Numbers are finite floats (NaN/Inf are refused at the edge, before anything is staged).
Joint-state fields follow sensor_msgs/JointState (`name`, `position`, `velocity`, `effort`).
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    model_validator,
)
from pydantic_core import PydanticCustomError

from service.core.commands.entities import EntityState
from service.core.commands.rules import BadJointState, joint_state
from service.core.schema_fields import (
    Delta,
    FiniteFloat,
    JointKey,
    JointRef,
    Paired,
    Strict,
    WorldId,
    default_spec,
    equal_lengths,
    joint_names,
    json_int,
    non_null,
    paired_config,
)
from service.core.types import NJOINT, JointSpec, Mode

MAX_STEP_TICKS = 100_000


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
    pending_target: list[float] | None = Field(
        None,
        description="only while paused: the targets as of every accepted command, which the "
        "next step puts in effect (`target` is what the last step used) [rad]",
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
    409: "the request does not fit the current state (e.g. step while not paused)",
    413: "the body is over the size limit",
    429: "a lease's commands came faster than its rate (all its connections together)",
    503: "the engine is starting, failed or is rebuilding a shard; or too many clients at once",
}


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """`responses=` for a route: the error statuses it can answer (422 FastAPI adds itself)."""
    return {code: {"model": ErrorReply, "description": _ERROR_MEANING[code]} for code in codes}


# Statuses every /v1 route can answer (engine not ready, client cap, token and origin checks).
ANY = (401, 403, 429, 503)
WITH_BODY = (*ANY, 400, 413)


# -- requests ---------------------------------------------------------------------------------
#
# The JSON Schema of every request states every rule the server enforces (joint names, equal
# lengths, which of increment's two shapes, strict integers), so that what the schema calls
# valid is accepted and what it calls invalid is refused: schemathesis holds us to that
# (tests/test_contract.py).

MAX_BATCH_WORLDS = 64  # worlds per POST /v1/targets; the schema lists every allowed length


class IncrementRequest(Strict):
    """One joint (`joint` + `delta`) or several (`deltas`): the seed's Up/Down buttons."""

    joint: JointRef | None = None
    delta: Delta | None = None
    deltas: Annotated[dict[JointKey, Delta], Field(min_length=1)] | None = None

    @staticmethod
    def _schema(schema: dict[str, Any]) -> None:
        # Exactly one of the two shapes, and no nulls (the validator below refuses them too).
        props = schema.pop("properties")
        plain = {k: non_null(v) for k, v in props.items()}
        schema.pop("additionalProperties", None)
        schema["oneOf"] = [
            {
                "title": "one joint",
                "type": "object",
                "properties": {"joint": plain["joint"], "delta": plain["delta"]},
                "required": ["joint", "delta"],
                "additionalProperties": False,
            },
            {
                "title": "several joints",
                "type": "object",
                "properties": {"deltas": plain["deltas"]},
                "required": ["deltas"],
                "additionalProperties": False,
            },
        ]
        schema["examples"] = [
            {"joint": "elbow_joint", "delta": 0.1},
            {"deltas": {"elbow_joint": 0.1, "finger_joint": -0.1}},
        ]

    model_config = ConfigDict(extra="forbid", json_schema_extra=_schema)

    @model_validator(mode="before")
    @classmethod
    def _no_nulls(cls, data: Any) -> Any:
        if isinstance(data, dict):
            for key in ("joint", "delta", "deltas"):
                if key in data and data[key] is None:
                    raise ValueError(f"`{key}` may be left out but not null")
        return data

    @model_validator(mode="after")
    def _one_form(self) -> IncrementRequest:
        single = self.joint is not None or self.delta is not None
        if single == (self.deltas is not None):
            raise ValueError("give either `joint` and `delta`, or `deltas`")
        if single and (self.joint is None or self.delta is None):
            raise ValueError("`joint` and `delta` go together")
        return self

    def as_mapping(self) -> dict[str | int, float]:
        if self.deltas is not None:
            return dict(self.deltas)
        assert self.joint is not None and self.delta is not None
        return {self.joint: self.delta}


class JointTargets(Strict):
    """sensor_msgs/JointState-shaped: a subset of names is allowed, others keep their targets;
    with no names (left out or empty), one position per joint in joint order, as the seed's
    Isaac subscriber read them. The rule is service.core.commands.rules.joint_state."""

    name: list[JointKey] = Field(
        default_factory=list, max_length=NJOINT, json_schema_extra={"uniqueItems": True}
    )
    position: list[FiniteFloat] = Field(min_length=1, max_length=NJOINT)

    @staticmethod
    def _schema(schema: dict[str, Any]) -> None:
        branches = equal_lengths("name", "position", range(1, NJOINT + 1))
        for branch in branches:
            branch["required"] = ["name"]
        nameless = {"minItems": NJOINT, "maxItems": NJOINT}
        branches.append({"properties": {"name": {"maxItems": 0}, "position": nameless}})
        schema["oneOf"] = branches
        # A joint named twice, once by name and once by index ("5" is wrist_3_joint), is a
        # repeat too: JSON Schema's uniqueItems cannot see it, so each such pair is excluded.
        schema["not"] = {
            "anyOf": [
                {
                    "required": ["name"],
                    "properties": {
                        "name": {
                            "allOf": [{"contains": {"const": n}}, {"contains": {"const": str(i)}}]
                        }
                    },
                }
                for i, n in enumerate(joint_names())
            ]
        }
        schema["examples"] = [
            {"name": ["elbow_joint", "finger_joint"], "position": [1.2, 0.35]},
            {"position": [0, -1.57, 1.57, -1.57, -1.57, 0, 0]},
        ]

    # JointState also carries header/velocity/effort: allowed, and ignored
    model_config = ConfigDict(extra="allow", json_schema_extra=_schema)

    @model_validator(mode="before")
    @classmethod
    def _the_rule(cls, data: Any) -> Any:
        """The one JointState rule, so that HTTP refuses with the same words as every surface."""
        if isinstance(data, dict):
            try:
                joint_state(default_spec(), data.get("name", []), data.get("position"))
            except BadJointState as exc:
                raise PydanticCustomError("joint_state", "{rule}", {"rule": str(exc)}) from None
        return data


class BatchTargets(Paired):
    """Full 7-joint targets for many worlds in one request, applied at one tick boundary."""

    PAIR = ("worlds", "position")
    worlds: list[WorldId] = Field(
        min_length=1,
        max_length=MAX_BATCH_WORLDS,
        json_schema_extra={"uniqueItems": True},
        description=f"distinct world ids, at most {MAX_BATCH_WORLDS} per request",
    )
    position: list[Annotated[list[FiniteFloat], Field(min_length=7, max_length=7)]] = Field(
        min_length=1, max_length=MAX_BATCH_WORLDS, description="one row of 7 targets per world"
    )

    model_config = paired_config(
        PAIR,
        MAX_BATCH_WORLDS,
        {"worlds": [0, 1], "position": [[0, -1.57, 1.57, -1.57, -1.57, 0, 0]] * 2},
    )


class ResetRequest(Strict):
    worlds: list[WorldId] | None = Field(default=None, description="omit for all worlds")

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"worlds": [0, 3]}]})


class ModeRequest(Strict):
    mode: Mode

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"mode": "fast"}]})


class StepRequest(Strict):
    ticks: json_int(minimum=1, maximum=MAX_STEP_TICKS) = 1  # type: ignore[valid-type]

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"ticks": 60}]})


# -- snapshots and recordings -----------------------------------------------------------------

# Names become file names under the data directory (see service/persistence/snapshots.py).
SNAPSHOT_NAME = r"^[A-Za-z0-9_][A-Za-z0-9._-]{0,63}$"
SnapshotName = Annotated[
    str,
    Field(
        pattern=SNAPSHOT_NAME,
        min_length=1,
        max_length=64,
        description="1-64 letters, digits, '.', '_', '-'; not starting with '.' or '-'",
    ),
]


class SnapshotRequest(Strict):
    name: SnapshotName

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"name": "before"}]})


class RecordingRequest(Strict):
    name: SnapshotName = Field(description="file <data-dir>/recordings/<name>.mcap")
    worlds: str | None = Field(
        default=None, description="worlds whose states are recorded, e.g. '0-7,12'; default first 8"
    )
    rate: float = Field(default=30.0, gt=0, le=1000, description="states per simulated second")

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"name": "run1", "worlds": "0-3", "rate": 30}]},
    )


class RecordingStatus(BaseModel):
    """What GET /v1/recordings/current shows (service/persistence/recorder.py makes it)."""

    path: str
    worlds: list[int]
    every_ticks: int = Field(description="a state every this many ticks")
    start_tick: int
    active: bool = Field(description="still writing")
    written: int = Field(description="items written so far")
    error: str | None = Field(description="why the recording stopped early, if it did")


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
