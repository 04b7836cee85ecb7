"""Settings and ARMFLEET_* environment variables as Markdown, from the pydantic Settings model.

Why from the model: the variable names, types, defaults, limits and descriptions are those the
service validates at start, and `armfleet serve`'s options are built from the same fields.
"""

from __future__ import annotations

import enum
import re
from typing import Any

_LIMITS = (("ge", "≥"), ("gt", ">"), ("le", "≤"), ("lt", "<"))


def _type(annotation: Any) -> str:
    text = getattr(annotation, "__name__", None) if isinstance(annotation, type) else None
    text = text or str(annotation)
    text = re.sub(r"\b(typing|pathlib|service\.core\.types)\.", "", text)
    text = text.replace("NoneType", "None")
    return text.replace("|", "\\|")


def _default(value: Any) -> str:
    if isinstance(value, enum.Enum):
        value = value.value
    if value is None:
        return "unset"
    if isinstance(value, float):
        return f"{value:g}"
    text = str(value)
    return "(empty)" if text in ("", "[]") else text


def _limits(field: Any) -> str:
    found = []
    for meta in field.metadata:
        for attr, word in _LIMITS:
            if getattr(meta, attr, None) is not None:
                value = getattr(meta, attr)
                found.append(f"{word} {value:,}" if isinstance(value, int) else f"{word} {value:g}")
    return ", ".join(found)


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def render() -> str:
    from service.cli import app
    from service.core.settings import Settings

    serve = next(
        c for c in app.registered_commands if c.callback and c.callback.__name__ == "serve"
    )
    options = set(serve.callback.__annotations__) if serve.callback else set()
    prefix = Settings.model_config.get("env_prefix", "")
    lines = [
        "Generated from the settings model (`service/core/settings.py`). Every field is read "
        f"from an environment variable `{prefix}NAME`; an `armfleet serve` option the user "
        "typed wins over the variable, which wins over the default.",
        "",
        "| variable | `serve` option | type | default | limits | what |",
        "|---|---|---|---|---|---|",
    ]
    for name, field in Settings.model_fields.items():
        option = f"`--{name.replace('_', '-')}`" if name in options else "–"
        lines.append(
            f"| `{prefix}{name.upper()}` | {option} | `{_type(field.annotation)}` "
            f"| `{_default(field.default)}` | {_limits(field)} | {_cell(field.description or '')} |"
        )
    return "\n".join(lines)
