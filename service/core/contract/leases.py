"""Request and reply bodies of the lease routes (/v1/leases); the rules are in leases.py and
stated here too, so that what the schema calls valid is what the service takes."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, StrictInt, model_validator

from service.core.access.leases import MAX_LABEL, MAX_WAIT_S
from service.core.commands.fields import Strict

WorldId = Annotated[StrictInt, Field(ge=0)]
Seconds = Annotated[float, Field(gt=0, allow_inf_nan=False, description="time to live [s]")]


class LeaseRequest(Strict):
    """Ask for `count` free worlds, or for the worlds named in `worlds` (exactly one of them)."""

    count: Annotated[StrictInt, Field(ge=1)] | None = None
    worlds: Annotated[list[WorldId], Field(min_length=1)] | None = None
    ttl_s: Seconds = 600.0
    label: Annotated[str, Field(max_length=MAX_LABEL)] = ""
    wait_s: Annotated[float, Field(ge=0, le=MAX_WAIT_S, allow_inf_nan=False)] = Field(
        0.0, description="seconds to wait for free worlds before refusing"
    )

    @staticmethod
    def _schema(schema: dict[str, Any]) -> None:
        for key in ("count", "worlds"):  # present means a value, never null
            prop = schema["properties"][key]
            prop.update(next(x for x in prop.pop("anyOf") if x.get("type") != "null"))
            prop.pop("default", None)
        schema["oneOf"] = [{"required": ["count"]}, {"required": ["worlds"]}]
        schema["examples"] = [{"count": 1, "ttl_s": 3600, "label": "alice"}]

    model_config = ConfigDict(extra="forbid", json_schema_extra=_schema)

    @model_validator(mode="after")
    def _one_form(self) -> LeaseRequest:
        if (self.count is None) == (self.worlds is None):
            raise ValueError("give either `count` or `worlds`")
        return self


class RenewRequest(Strict):
    """Live `ttl_s` more seconds from now."""

    ttl_s: Seconds = 600.0

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"ttl_s": 3600}]})


class LeaseReply(BaseModel):
    """A lease as its holder and the administrator see it; `token` only in the grant's reply."""

    id: str
    worlds: list[int]
    label: str
    ttl_s: float
    expires_in_s: float
    expires_at: float = Field(description="wall clock, seconds since the epoch")
    granted_at: float
    token: str | None = Field(
        None, description="send as `Authorization: Bearer <token>`; shown once, never again"
    )


class LeaseList(BaseModel):
    leases: list[LeaseReply]
