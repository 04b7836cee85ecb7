"""What the UR surface is asked for: on or off, which worlds, and on which addresses.

Why a model of its own: the surface is built from these plus the `ServiceFacts` (the bind
address's consent, the number of worlds, access); the world list and the address list are
checked against the number of worlds when the surface is built (addresses.py names the bad
part). A field's `validation_alias` is its flat name (`ARMFLEET_UR_ADDRESSES`,
`--ur-addresses`).
"""

from __future__ import annotations

from pydantic import BaseModel

from service.core.process.flat_names import BY_BOTH, flat


class UrSettings(BaseModel):
    """UR controller ports per world (`--ur`, `--ur-worlds`, `--ur-addresses`)."""

    model_config = BY_BOTH

    enabled: bool = flat(
        "ur",
        False,
        "give every world a UR controller's ports (RTDE 30004, Dashboard 29999, 30001-30003) "
        "on an address of its own",
    )
    worlds: str | None = flat("ur_worlds", None, "worlds with UR ports, e.g. 0-31 (default: all)")
    addresses: str | None = flat(
        "ur_addresses",
        None,
        "IPv4 addresses for the --ur-worlds in order, e.g. 10.0.0.10-10.0.0.41 or "
        "10.0.0.10,10.0.0.12 (default: world w on 127.0.(1 + w // 254).(1 + w % 254)); "
        "addresses off loopback need --token or --insecure, as --host does",
    )
