"""What access asks of the settings: the administrator's token, who may read, origins, the
client and command limits, and leases. Why a model of its own: the access policy reads these
and nothing else, so it depends on no other part of the service's settings.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class AccessSettings(BaseModel):
    """Access and leases (`ARMFLEET_TOKEN`, `ARMFLEET_LEASES`, ...: the flat names are kept)."""

    model_config = ConfigDict(extra="forbid")

    token: str | None = Field(
        None, description="token that writes (and with token_reads, reads) must present"
    )
    insecure: bool = Field(False, description="allow a non-loopback bind without a token")
    token_reads: bool = Field(False, description="reads need the token too")
    allow_origins: list[str] = Field(
        [],
        description="browser origins besides the service's own that may command (exact match)",
    )
    max_clients: int = Field(
        256, ge=0, description="clients served at once (HTTP requests + sockets); 0 = no limit"
    )
    command_rate: float = Field(
        200.0,
        gt=0,
        description="commands per second per connection (a socket, or an HTTP keep-alive "
        "connection: 429 beyond it)",
    )
    command_burst: int | None = Field(
        None, ge=1, description="commands a connection may send at once (default: one second's)"
    )
    leases: Literal["off", "optional", "required"] = Field(
        "off",
        description="lend worlds with tokens of their own (POST /v1/leases). optional: a leased "
        "world answers only to its lease (and --token); required: every command needs a lease "
        "token or --token",
    )
    lease_reset: Literal["both", "start", "end", "none"] = Field(
        "both", description="reset a leased world to home when its lease starts, ends, both"
    )
    lease_max_ttl_s: float = Field(
        86_400.0, gt=0, le=31 * 86_400, description="longest time to live a lease may have [s]"
    )

    @model_validator(mode="after")
    def _required_leases_have_an_administrator(self) -> AccessSettings:
        if self.leases == "required" and not self.token:
            raise ValueError("leases required: give --token, the administrator's (who lends)")
        return self
