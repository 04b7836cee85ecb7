"""Settings and ARMFLEET_* environment variables as Markdown, from the pydantic settings models.

Why from the models: the variable names, types, defaults, limits and descriptions are those the
service validates at start, and `armfleet serve`'s options are built from the same fields. The
fields live in sections beside their owners (service/settings.py says which); users type flat
names, so the table is flat, with the section and the module each field is read from.
"""

from __future__ import annotations

import enum
import inspect
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
    from service.settings import ENV_PREFIX, Settings, flat_fields

    serve = next(
        c for c in app.registered_commands if c.callback and c.callback.__name__ == "serve"
    )
    # serve's options are its signature's parameters (cli._serve_signature), not annotations
    options = set(inspect.signature(serve.callback).parameters) if serve.callback else set()
    prefix = ENV_PREFIX
    lines = [
        "Generated from the settings models (the sections of `service/settings.py`, each "
        "beside its owner; the table says where). Every field is read from an environment "
        f"variable `{prefix}NAME`; an `armfleet serve` option the user typed wins over the "
        "variable, which wins over the default. In code a field is `settings.SECTION.FIELD` "
        "(the column *in code*).",
        "",
        "| variable | `serve` option | in code | type | default | limits | what |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, (section, attr, field) in flat_fields().items():
        option = f"`--{name.replace('_', '-')}`" if name in options else "–"
        model = Settings.model_fields[section].annotation
        where = f"{model.__module__}.{model.__name__}" if model is not None else section
        lines.append(
            f"| `{prefix}{name.upper()}` | {option} | `{section}.{attr}` "
            f"<br><small>`{where}`</small> | `{_type(field.annotation)}` "
            f"| `{_default(field.default)}` | {_limits(field)} | {_cell(field.description or '')} |"
        )
    return "\n".join(lines)
