"""The HTTP API reference as Markdown, from the OpenAPI schema the app serves at /openapi.json.

Why rendered here and not by a plugin: the schema comes from `create_app()` (which builds the
routes without starting an engine), so the page is exactly what a running server describes,
and a few dozen lines of Markdown need no JavaScript viewer and nothing from the network.
"""

from __future__ import annotations

import json
import re
from typing import Any

METHODS = ("get", "put", "post", "delete", "patch")


def schema() -> dict[str, Any]:
    """The app's OpenAPI document; the app is built, never started."""
    from service.app import create_app

    return create_app().openapi()


def _ref_name(ref: str) -> str:
    return ref.rsplit("/", 1)[-1]


def _anchor(name: str) -> str:
    return f"schema-{name.lower()}"


def type_of(s: dict[str, Any]) -> str:
    """A schema in a few words: `integer`, `array of number`, [`WorldState`](#...)."""
    if "$ref" in s:
        name = _ref_name(s["$ref"])
        return f"[`{name}`](#{_anchor(name)})"
    for key, word in (("anyOf", " or "), ("oneOf", " or "), ("allOf", " and ")):
        if key in s:
            return word.join(type_of(x) for x in s[key])
    if "enum" in s:
        return " \\| ".join(f"`{json.dumps(v)}`" for v in s["enum"])
    if "const" in s:
        return f"`{json.dumps(s['const'])}`"
    t = s.get("type", "any")
    if t == "array":
        return f"array of {type_of(s.get('items', {}))}"
    if (
        t == "object"
        and "additionalProperties" in s
        and isinstance(s["additionalProperties"], dict)
    ):
        return f"object of {type_of(s['additionalProperties'])}"
    return f"`{t}`"


LIMITS = (
    ("minimum", "≥ {}"),
    ("exclusiveMinimum", "> {}"),
    ("maximum", "≤ {}"),
    ("exclusiveMaximum", "< {}"),
    ("minItems", "at least {} items"),
    ("maxItems", "at most {} items"),
    ("minLength", "at least {} characters"),
    ("maxLength", "at most {} characters"),
    ("pattern", "matches `{}`"),
)


def limits(s: dict[str, Any]) -> str:
    out = [fmt.format(s[k]) for k, fmt in LIMITS if k in s]
    if "default" in s:
        out.append(f"default `{json.dumps(s['default'])}`")
    return "; ".join(out)


def _cell(text: Any) -> str:
    return " ".join(str(text or "").split()).replace("|", "\\|")


def _parameters(op: dict[str, Any]) -> list[str]:
    params = op.get("parameters") or []
    if not params:
        return []
    lines = ["| parameter | in | type | required | what |", "|---|---|---|---|---|"]
    for p in params:
        s = p.get("schema", {})
        what = "; ".join(x for x in (p.get("description") or s.get("description"), limits(s)) if x)
        lines.append(
            f"| `{p['name']}` | {p['in']} | {type_of(s)} | {'yes' if p.get('required') else 'no'}"
            f" | {_cell(what)} |"
        )
    return [*lines, ""]


def _body(op: dict[str, Any]) -> list[str]:
    body = op.get("requestBody")
    if not body:
        return []
    content = body.get("content", {})
    kinds = ", ".join(f"{type_of(c.get('schema', {}))} ({mt})" for mt, c in content.items())
    return [f"Body: {kinds}", ""]


def _responses(op: dict[str, Any]) -> list[str]:
    lines = ["| status | what | body |", "|---|---|---|"]
    for status, r in sorted(op.get("responses", {}).items()):
        content = r.get("content", {}).get("application/json", {})
        kind = type_of(content["schema"]) if content.get("schema") else ""
        lines.append(f"| {status} | {_cell(r.get('description'))} | {kind} |")
    return [*lines, ""]


def operations(doc: dict[str, Any]) -> list[str]:
    lines: list[str] = []
    tags: dict[str, list[tuple[str, str, dict[str, Any]]]] = {}
    for path, ops in doc["paths"].items():
        for method in METHODS:
            if method in ops:
                tag = (ops[method].get("tags") or ["service"])[0]
                tags.setdefault(tag, []).append((method, path, ops[method]))
    for tag, ops in tags.items():
        lines += [f"## {tag}", ""]
        for method, path, op in ops:
            lines += [f"### `{method.upper()} {path}`", ""]
            lines += [_cell(op.get("summary")), ""]
            if op.get("description"):
                lines += [op["description"].strip(), ""]
            lines += _parameters(op) + _body(op) + _responses(op)
    return lines


def schemas(doc: dict[str, Any]) -> list[str]:
    lines = ["## Schemas", ""]
    for name, s in sorted(doc.get("components", {}).get("schemas", {}).items()):
        lines += [f"### `{name}` {{ #{_anchor(name)} }}", ""]
        if s.get("description"):
            lines += [_cell(s["description"]), ""]
        props = s.get("properties")
        if not props:
            lines += [f"Type: {type_of(s)}", ""]
            continue
        required = set(s.get("required", []))
        lines += ["| field | type | required | what |", "|---|---|---|---|"]
        for field, p in props.items():
            what = "; ".join(x for x in (p.get("description"), limits(p)) if x)
            lines.append(
                f"| `{field}` | {type_of(p)} | {'yes' if field in required else 'no'} "
                f"| {_cell(what)} |"
            )
        lines.append("")
    return lines


def render() -> str:
    doc = schema()
    info = doc["info"]
    head = [
        f"Generated from the OpenAPI {doc['openapi']} schema of {info['title']} "
        f"{info['version']} (what a running server serves at `/openapi.json`, browsable at "
        "`/docs`).",
        "",
        # a list right under a line of text needs a blank line to be a list in Markdown
        re.sub(r"(?<=[^\n])\n\* ", "\n\n* ", info.get("description", "").strip()),
        "",
    ]
    return "\n".join(head + operations(doc) + schemas(doc))
