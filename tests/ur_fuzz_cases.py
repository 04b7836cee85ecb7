"""Seeded RTDE fuzz cases for tests/test_ur_fuzz.py: odd and malformed packages, each with the
answers a UR controller may give it.

Why a seeded generator and not hypothesis: the cases run against one live server whose
connections carry state (recipes set up, streaming started, inputs held by another client), so
a shrunk example would not replay; a seed replays exactly. What each case may get back is
written from UR's RTDE guide (package types, protocol version 2, the variable types, recipe id
0 for a recipe with a NOT_FOUND or IN_USE variable), never read from armfleet's code.

Outcomes (what came back before the sentinel, tests/test_ur_fuzz.py):
  answer   the reply of V, v, S or P
  recipe   an output or input setup answered with a recipe id >= 1
  refused  a setup answered with recipe id 0 (NOT_FOUND, IN_USE, a frequency out of range)
  error    a text message of level ERROR and nothing else
  silent   nothing (an input data package applied, a client's text message logged)
  closed   the controller closed the connection
"""

from __future__ import annotations

import math
import random
import struct
from dataclasses import dataclass, field
from typing import Any

# UR's RTDE guide (e-Series): names and types, independent of armfleet's tables
OUTPUTS = {
    "timestamp": "DOUBLE",
    "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D",
    "target_q": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",
    "robot_mode": "INT32",
    "safety_mode": "INT32",
    "runtime_state": "UINT32",
    "speed_scaling": "DOUBLE",
    "actual_digital_input_bits": "UINT64",
    "joint_mode": "VECTOR6INT32",
    "payload_cog": "VECTOR3D",
    "output_int_register_5": "INT32",
    "output_double_register_40": "DOUBLE",
    "output_bit_register_70": "BOOL",
}
SIZE = {"BOOL": 1, "UINT32": 4, "INT32": 4, "DOUBLE": 8}
CODE = {"BOOL": "B", "UINT32": "I", "INT32": "i", "DOUBLE": "d"}
# ur_rtde's control interface writes these (its script reads the command and arguments here)
CONTROL = ("input_int_register_0", *(f"input_double_register_{i}" for i in range(6)))
ODD_DOUBLES = (math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, 1.5, 7.0, -0.0)
ODD_INTS = (-(2**31), 2**31 - 1, -1, 0, 255, 65535)
KNOWN = set(b"VvMUOISP")
ANSWER, RECIPE, REFUSED = frozenset({"answer"}), frozenset({"recipe"}), frozenset({"refused"})
ERROR, SILENT = frozenset({"error"}), frozenset({"silent"})
CLOSED, CUT = frozenset({"closed"}), frozenset({"cut"})  # cut: the client closed mid-package


def package(kind: int, payload: bytes = b"") -> bytes:
    return struct.pack(">HB", 3 + len(payload), kind) + payload


def input_type(name: str) -> str:
    if name.startswith("input_int_register_"):
        return "INT32"
    if name.startswith("input_bit_register_"):
        return "BOOL"
    return "UINT32" if name == "speed_slider_mask" else "DOUBLE"


@dataclass
class Case:
    """Bytes to send, the outcomes a controller may answer with, and what else to check."""

    category: str
    data: bytes
    allowed: frozenset[str]
    requests_v: int = 0  # 'v' requests in `data` (their answers are not the sentinel's)
    types: str | None = None  # the exact type list a setup answer must carry
    last: bool = False  # the connection ends with it (a truncated package: the client closes)
    split: bool = False  # sent in two writes
    names: tuple[str, ...] = ()  # an input setup's names (kept with the recipe id it gets)


@dataclass
class Connection:
    """What one fuzz connection has set up, as the generator tracks it."""

    started: bool = False
    inputs: dict[int, tuple[str, ...]] = field(default_factory=dict)  # recipe id → names
    outputs: int = 0


class Fuzz:
    """The next case for a connection, from one seeded stream; `held` are names another
    connection to the same world writes (IN_USE for every other connection)."""

    def __init__(self, seed: int, held: tuple[str, ...]) -> None:
        self.rng = random.Random(seed)
        self.held = set(held)

    def _bytes(self, lo: int, hi: int) -> bytes:
        return self.rng.randbytes(self.rng.randint(lo, hi))

    def _garbage_name(self) -> str:
        alphabet = "abcdefghijklmnopqrstuvwxyz_0123456789"
        return "".join(self.rng.choice(alphabet) for _ in range(self.rng.randint(1, 30)))

    def _input_names(self) -> list[str]:
        """1..4 input names: registers (now and then one of ur_rtde's control registers,
        which another client holds), the speed slider with its mask."""
        r = self.rng
        pool = [
            f"input_int_register_{r.randint(1, 47)}",
            f"input_double_register_{r.randint(6, 47)}",
            f"input_bit_register_{r.randint(64, 127)}",
            "speed_slider_mask",
            "speed_slider_fraction",
        ]
        names = r.sample(pool, r.randint(1, 3))
        if r.random() < 0.2:
            names.append(r.choice(CONTROL))
        if "speed_slider_fraction" in names and "speed_slider_mask" not in names:
            names.append("speed_slider_mask")
        return names

    def _value(self, kind: str, name: str) -> bytes:
        r = self.rng
        if name == "speed_slider_mask":
            return struct.pack(">I", r.choice((0, 1, 0xFFFFFFFF)))
        if name == "speed_slider_fraction":  # never a value in [0, 1): the speed stays 1.0
            return struct.pack(">d", r.choice((math.nan, math.inf, -math.inf, 1.0, 1.5, 1e300)))
        if kind == "DOUBLE":
            return struct.pack(">d", r.choice(ODD_DOUBLES) if r.random() < 0.7 else r.random())
        if kind == "INT32":
            return struct.pack(">i", r.choice(ODD_INTS))
        if kind == "BOOL":
            return bytes([r.randint(0, 255)])  # a bool byte that is neither 0 nor 1, too
        return struct.pack(">I", r.getrandbits(32))

    def next(self, c: Connection) -> Case:
        """One case, its category drawn by weight (a connection's last case ends it)."""
        pick = self.rng.random()
        for weight, make in self._categories:
            if pick < weight:
                return make(c)
            pick -= weight
        return self._cut(c)

    @property
    def _categories(self) -> tuple[tuple[float, Any], ...]:
        return (
            (0.06, self._version),
            (0.10, self._unknown_type),
            (0.03, self._control_version),
            (0.11, self._outputs),
            (0.10, self._inputs),
            (0.26, self._data),
            (0.06, self._empty_data),
            (0.08, self._text),
            (0.08, self._start_pause),
            (0.05, self._huge),
            (0.03, self._split),
        )

    def _version(self, c: Connection) -> Case:
        """Protocol version: the wrong size, or another version (answered "not accepted")."""
        r = self.rng
        if r.random() < 0.5:
            body = r.choice((b"", b"\x02", b"\x00\x02\x00", self._bytes(3, 9)))
            return Case("V wrong size", package(ord("V"), body), ERROR)
        version = r.choice((0, 1, 2, 3, 65535))
        return Case("V version", package(ord("V"), struct.pack(">H", version)), ANSWER)

    def _unknown_type(self, c: Connection) -> Case:
        kind = self.rng.choice([k for k in range(256) if k not in KNOWN])
        return Case("unknown type", package(kind, self._bytes(0, 64)), ERROR)

    def _control_version(self, c: Connection) -> Case:
        return Case("v with a body", package(ord("v"), self._bytes(0, 8)), ANSWER, requests_v=1)

    def _outputs(self, c: Connection) -> Case:
        """Output setups: unknown names, odd frequencies, short and odd bodies, valid ones."""
        r = self.rng
        hz = struct.pack(">d", r.uniform(1, 500))
        names = r.sample(sorted(OUTPUTS), r.randint(1, 4))
        form = r.randrange(5)
        if form == 0:
            names.insert(r.randrange(len(names) + 1), self._garbage_name() + "_x")
            body = hz + ",".join(names).encode()
            return Case("O unknown variable", package(ord("O"), body), REFUSED, types="NOT_FOUND")
        if form == 1:
            bad = struct.pack(">d", r.choice((math.nan, math.inf, -1.0, 0.0, 501.0, 1e9)))
            return Case("O bad frequency", package(ord("O"), bad + b"timestamp"), REFUSED)
        if form == 2:
            return Case("O short", package(ord("O"), self._bytes(0, 7)), ERROR)
        if form == 3:
            body = r.choice((b"", b",,,", bytes([0xFF, 0xFE]) + b"timestamp", b"a" * 2100))
            return Case("O bad names", package(ord("O"), hz + body), ERROR)
        types = ",".join(OUTPUTS[n] for n in names)
        want = REFUSED if c.started else RECIPE  # no setup while synchronising
        c.outputs += not c.started
        return Case("O valid", package(ord("O"), hz + ",".join(names).encode()), want, types=types)

    def _inputs(self, c: Connection) -> Case:
        """Input setups: unknown, duplicated, held by another client (IN_USE), valid."""
        r = self.rng
        names = self._input_names()
        form = r.random()
        if form < 0.2:
            names.append(self._garbage_name() + "_x")
            body = ",".join(names).encode()
            return Case("I unknown variable", package(ord("I"), body), REFUSED, types="NOT_FOUND")
        if form < 0.35:
            names.append(names[0])
            return Case("I duplicate", package(ord("I"), ",".join(names).encode()), REFUSED)
        body = ",".join(names).encode()
        if self.held & set(names):
            return Case("I in use", package(ord("I"), body), REFUSED, types="IN_USE")
        types = ",".join(input_type(n) for n in names)
        return Case("I valid", package(ord("I"), body), RECIPE, types=types, names=tuple(names))

    def _data(self, c: Connection) -> Case:
        """Input data: NaN, infinities and extremes to a recipe, wrong sizes, unknown ids."""
        r = self.rng
        if c.inputs and r.random() < 0.85:
            rid = r.choice(sorted(c.inputs))
            names = c.inputs[rid]
            values = b"".join(self._value(input_type(n), n) for n in names)
            if r.random() < 0.8:
                return Case("U odd values", package(ord("U"), bytes([rid]) + values), SILENT)
            if r.random() < 0.5:  # short of its fields: refused
                cut = values[: r.randrange(len(values))]
                return Case("U wrong size", package(ord("U"), bytes([rid]) + cut), ERROR)
            # past its fields: applied by them, the rest ignored (rtde_session.py says why)
            extra = values + self._bytes(1, 48)
            return Case("U longer", package(ord("U"), bytes([rid]) + extra), SILENT)
        rid = r.choice([i for i in range(256) if i not in c.inputs])
        body = bytes([rid]) + self._bytes(0, 40)
        return Case("U unknown recipe", package(ord("U"), body), ERROR)

    def _empty_data(self, c: Connection) -> Case:
        return Case("U empty", package(ord("U")), ERROR)

    def _text(self, c: Connection) -> Case:
        """A client's text message: well formed, or lengths past its end."""
        r = self.rng
        msg, src = self._bytes(0, 40), self._bytes(0, 10)
        good = bytes([len(msg)]) + msg + bytes([len(src)]) + src + bytes([r.randint(0, 3)])
        if r.random() < 0.5:
            return Case("M text", package(ord("M"), good), SILENT)
        return Case("M short", package(ord("M"), good[: r.randrange(len(good))]), ERROR)

    def _start_pause(self, c: Connection) -> Case:
        kind = self.rng.choice("SP")
        c.started = kind == "S"  # S starts even with no output recipe; P pauses
        return Case(kind, package(ord(kind), self._bytes(0, 2)), ANSWER)

    def _huge(self, c: Connection) -> Case:
        """The largest length the header can say, with a body that fills it."""
        kind = self.rng.choice([ord("O"), ord("I"), ord("U"), ord("M"), 0x7F])
        allowed = ERROR | SILENT if kind == ord("M") else ERROR  # random text may be well formed
        return Case("huge package", package(kind, self._bytes(65532, 65532)), allowed)

    def _split(self, c: Connection) -> Case:
        return Case("V split", package(ord("V"), struct.pack(">H", 2)), ANSWER, split=True)

    def _cut(self, c: Connection) -> Case:
        """The connection's last case: a size below the header's own (the controller closes),
        or a package cut short (huge or not) after which the client closes."""
        r = self.rng
        form = r.randrange(3)
        if form == 0:
            bad = struct.pack(">HB", r.randint(0, 2), ord("V"))
            return Case("size below header", bad, CLOSED, last=True)
        size = 65535 if form == 1 else r.randint(10, 400)
        whole = package(r.choice(b"OIUMZ"), self._bytes(size - 3, size - 3))
        name = "huge length, cut short" if form == 1 else "truncated"
        return Case(name, whole[: r.randint(1, len(whole) - 1)], CUT, last=True)
