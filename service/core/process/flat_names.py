"""How a settings section declares a field whose code name differs from the flat name users
type (`ARMFLEET_FOXGLOVE_PORT`, `--foxglove-port`, `Settings(foxglove_port=...)`).

Why here: every section (core's, the engines', persistence's, the surfaces') declares its
fields the same way, and the process's environment and command line are where flat names
come from; this room sits under every other, so each section can import it.
"""

from __future__ import annotations

from typing import Any

from pydantic import ConfigDict, Field

# A section takes a field by its code name or its flat name, and nothing else.
BY_BOTH = ConfigDict(extra="forbid", validate_by_name=True, validate_by_alias=True)


def flat(name: str, default: Any, description: str, **limits: Any) -> Any:
    """A field whose flat name is `name` (pydantic's validation alias: the environment
    variable, the serve option and the flat keyword all use it)."""
    return Field(default, validation_alias=name, description=description, **limits)
