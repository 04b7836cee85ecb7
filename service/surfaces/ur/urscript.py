"""A small reader of URScript lines: one function call each, with the robot's argument forms.

Not an interpreter: a line is `name(arg, ..., key=value, ...)`, where a value is a number, a
list `[1, 2, 3]`, a pose `p[x, y, z, rx, ry, rz]` or True/False. `bind` matches a call to a
function's signature (positional, then keywords, then defaults, as URScript does) and checks
every value: finite numbers, lists of the right length, poses where a pose is asked. What a
line that is not such a call (or a function outside `SIGNATURES`) gets is a `ScriptError`
naming it; the script ports refuse it with that text.

The functions and their defaults are UR's (URScript manual, e-Series 5.x): movej, movel,
speedj, speedl, servoj, stopj, stopl, set_tcp, set_payload.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

__all__ = ["SIGNATURES", "Call", "Pose", "ScriptError", "bind", "parse_line"]

MAX_LINE = 4096


class ScriptError(ValueError):
    """A line that is not a call armfleet carries out (the text says why, naming the function)."""


@dataclass(frozen=True)
class Pose:
    """p[x, y, z, rx, ry, rz]."""

    values: tuple[float, ...]


Value = float | bool | tuple[float, ...] | Pose


@dataclass(frozen=True)
class Call:
    name: str
    args: tuple[Value, ...] = ()
    kwargs: dict[str, Value] = field(default_factory=dict)


_TOKEN = re.compile(
    r"\s*(?:(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<name>[A-Za-z_]\w*)"
    r"|(?P<sym>[\[\](),=]))"
)


def _tokens(text: str) -> list[tuple[str, str]]:
    out, i = [], 0
    text = text.rstrip()
    while i < len(text):
        m = _TOKEN.match(text, i)
        if m is None or m.end() == i:
            raise ScriptError(f"cannot read {text[i : i + 20]!r}")
        kind = m.lastgroup or ""
        out.append((kind, m.group(kind)))
        i = m.end()
    return out


class _Reader:
    def __init__(self, tokens: list[tuple[str, str]]) -> None:
        self.t, self.i = tokens, 0

    def peek(self) -> tuple[str, str]:
        return self.t[self.i] if self.i < len(self.t) else ("end", "")

    def take(self, want: str | None = None) -> tuple[str, str]:
        tok = self.peek()
        if tok[0] == "end" or (want is not None and tok[1] != want):
            raise ScriptError(f"expected {want or 'a value'}, got {tok[1] or 'the end'!r}")
        self.i += 1
        return tok

    def value(self) -> Value:
        kind, text = self.peek()
        if kind == "num":
            self.i += 1
            return float(text)
        if kind == "name" and text in ("True", "False"):
            self.i += 1
            return text == "True"
        if kind == "name" and text == "p":
            self.i += 1
            return Pose(self.numbers())
        if text == "[":
            return self.numbers()
        raise ScriptError(f"{text!r} is not a number, list or pose (no variables or expressions)")

    def numbers(self) -> tuple[float, ...]:
        self.take("[")
        out: list[float] = []
        while self.peek()[1] != "]":
            kind, text = self.take()
            if kind != "num":
                raise ScriptError(f"{text!r} in a list: only numbers")
            out.append(float(text))
            if self.peek()[1] == ",":
                self.i += 1
        self.take("]")
        return tuple(out)


def parse_line(line: str) -> Call:
    """The call on one line (a trailing `# comment` is dropped); ScriptError otherwise."""
    if len(line) > MAX_LINE:
        raise ScriptError(f"a line longer than {MAX_LINE} characters")
    text = line.split("#", 1)[0].strip()
    r = _Reader(_tokens(text))
    kind, name = r.take()
    if kind != "name":
        raise ScriptError(f"{text[:40]!r} is not a function call")
    if r.peek()[1] != "(":
        raise ScriptError(f"{name}: not a function call (only calls are carried out)")
    r.take("(")
    args: list[Value] = []
    kwargs: dict[str, Value] = {}
    while r.peek()[1] != ")":
        if r.peek()[0] == "name" and r.i + 1 < len(r.t) and r.t[r.i + 1][1] == "=":
            key = r.take()[1]
            r.take("=")
            kwargs[key] = r.value()
        elif kwargs:
            raise ScriptError(f"{name}: a positional argument after a keyword one")
        else:
            args.append(r.value())
        if r.peek()[1] == ",":
            r.i += 1
        elif r.peek()[1] != ")":
            raise ScriptError(f"{name}: expected ',' or ')', got {r.peek()[1]!r}")
    r.take(")")
    if r.peek()[0] != "end":
        raise ScriptError(f"{name}: text after the call ({r.peek()[1]!r})")
    return Call(name, tuple(args), kwargs)


# name → ((parameter, kind, default), ...); kind: "q" six numbers (a pose is read as one too
# where UR allows it), "pose", "pose|q", "vec3", "num". No default: required.
_Q, _POSE, _EITHER, _V3, _N = "q", "pose", "pose|q", "vec3", "num"
_TR = (("t", _N, 0.0), ("r", _N, 0.0))
SIGNATURES: dict[str, tuple[tuple[str, str, Any], ...]] = {
    "movej": (("q", _EITHER, None), ("a", _N, 1.4), ("v", _N, 1.05), *_TR),
    "movel": (("pose", _EITHER, None), ("a", _N, 1.2), ("v", _N, 0.25), *_TR),
    "speedj": (("qd", _Q, None), ("a", _N, 1.4), ("t", _N, 0.0)),
    "speedl": (("xd", _Q, None), ("a", _N, 1.2), ("t", _N, 0.0), ("aRot", _N, 0.0)),
    "servoj": (
        ("q", _Q, None), ("a", _N, 0.0), ("v", _N, 0.0), ("t", _N, 0.002),
        ("lookahead_time", _N, 0.1), ("gain", _N, 300.0),
    ),
    "stopj": (("a", _N, None),),
    "stopl": (("a", _N, None), ("aRot", _N, 0.0)),
    "set_tcp": (("pose", _POSE, None),),
    "set_payload": (("m", _N, None), ("cog", _V3, (0.0, 0.0, 0.0))),
    "signal_async_progress": (("i", _N, None),),  # in ur_rtde's injected paths
}  # fmt: skip


def bind(call: Call) -> dict[str, Any]:
    """Parameter → value of `call` by its signature; ScriptError naming the function and the
    parameter for an unknown function, a missing, extra or ill-formed argument."""
    sig = SIGNATURES.get(call.name)
    if sig is None:
        raise ScriptError(f"{call.name}() is not carried out by armfleet")
    if len(call.args) > len(sig):
        raise ScriptError(f"{call.name}() takes at most {len(sig)} arguments")
    names = [s[0] for s in sig]
    unknown = set(call.kwargs) - set(names)
    if unknown:
        raise ScriptError(f"{call.name}() has no parameter {sorted(unknown)[0]!r}")
    out: dict[str, Any] = {}
    for i, (pname, kind, default) in enumerate(sig):
        if i < len(call.args):
            if pname in call.kwargs:
                raise ScriptError(f"{call.name}(): {pname} given twice")
            value: Any = call.args[i]
        elif pname in call.kwargs:
            value = call.kwargs[pname]
        elif default is None:
            raise ScriptError(f"{call.name}(): {pname} is missing")
        else:
            value = default
        out[pname] = _check(call.name, pname, kind, value)
    out["is_pose"] = isinstance(call.args[0] if call.args else call.kwargs.get(names[0]), Pose)
    return out


def _check(fn: str, pname: str, kind: str, value: Any) -> Any:
    where = f"{fn}(): {pname}"
    if kind == _N:
        if isinstance(value, bool) or not isinstance(value, float) or not math.isfinite(value):
            raise ScriptError(f"{where} must be a finite number, got {value!r}")
        return value
    vals = value.values if isinstance(value, Pose) else value
    if not isinstance(vals, tuple):
        raise ScriptError(f"{where} must be a list or pose, got {value!r}")
    size = 3 if kind == _V3 else 6
    if len(vals) != size or not all(math.isfinite(v) for v in vals):
        raise ScriptError(f"{where} must be {size} finite numbers, got {list(vals)}")
    if kind == _POSE and not isinstance(value, Pose):
        raise ScriptError(f"{where} must be a pose p[x, y, z, rx, ry, rz]")
    if kind == _Q and isinstance(value, Pose):
        raise ScriptError(f"{where} must be a list [...], not a pose")
    return list(vals)
