"""RTDE output values of one world at one tick, and the inputs a client writes.

What each output holds (the guide lists it): joint values are the six arm joints' (the
finger is not a UR joint). `actual_current`, `target_current` and `target_moment` hold the
actuator force MuJoCo applies to each joint [N·m] (armfleet has no motor currents);
`target_qd`/`target_qdd` are the rate of change of the position target over the last ticks
(the servos track position targets); TCP pose and speed come from `tcp_pose` with the world's
TCP offset as the core's tool table holds it (`kinematics.tools`: set by setTcp, set_tcp, REST
or WebSocket alike); `timestamp` is tick × tick length (simulated seconds since the service
started).
Outputs a simulated arm has no source for (temperatures, voltages, analog inputs, the
accelerometer, wrenches, euromap) are 0; the guide says so.

Why values are computed once per tick for every world (`rtde_frame`), and a package packed
once per (recipe, tick): a 500 Hz stream of a 60 Hz world sends the same tick several times,
and 32 programs ask for the same values of 32 worlds.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from service.surfaces.ur import rtde_variables as rv
from service.surfaces.ur.controller import Controller
from service.surfaces.ur.rtde_frame import Frame, FrameValues


class WorldTick:
    """One world's values at one frame's tick: the frame's rows for every world
    (`rtde_frame.FrameValues`, computed once per tick) and this world's controller."""

    __slots__ = ("ctl", "payload", "values", "w")

    def __init__(
        self, values: FrameValues, world: int, ctl: Controller, payload: Sequence[float]
    ) -> None:
        self.values, self.w, self.ctl, self.payload = values, world, ctl, payload

    @property
    def frame(self) -> Frame:
        return self.values.frame


_ZERO6, _ZERO3 = (0.0,) * 6, (0.0,) * 3
Reader = Callable[[WorldTick], Sequence[Any]]


def _row(name: str) -> Reader:
    return lambda t: getattr(t.values, name)[t.w]


def _tcp(which: str, part: int) -> Reader:
    return lambda t: getattr(t.values, which)[part][t.w]


READERS: dict[str, Reader] = {
    "timestamp": lambda t: t.values.timestamp,
    "actual_q": _row("q"),
    "actual_qd": _row("qd"),
    "actual_current": _row("effort"),
    "target_current": _row("effort"),
    "target_moment": _row("effort"),
    "target_q": _row("target"),
    "target_qd": _row("target_qd"),
    "target_qdd": _row("target_qdd"),
    "actual_TCP_pose": _tcp("actual_tcp", 0),
    "actual_TCP_speed": _tcp("actual_tcp", 1),
    "target_TCP_pose": _tcp("target_tcp", 0),
    "target_TCP_speed": _tcp("target_tcp", 1),
    "robot_mode": lambda t: (int(t.ctl.robot_mode),),
    "safety_mode": lambda t: (int(t.ctl.safety_mode),),
    "safety_status": lambda t: (int(t.ctl.safety_mode),),
    "safety_status_bits": lambda t: (t.ctl.safety_status_bits,),
    "robot_status_bits": lambda t: (t.ctl.robot_status_bits,),
    "runtime_state": lambda t: (t.ctl.runtime_state,),
    "joint_mode": lambda t: (t.ctl.joint_mode,) * 6,
    "speed_scaling": lambda t: (t.ctl.speed_scaling,),
    "target_speed_fraction": lambda t: (t.ctl.speed_fraction,),
    "actual_digital_output_bits": lambda t: (int(t.ctl.inputs.get("digital_outputs", 0)),),
    "standard_analog_output0": lambda t: (float(t.ctl.inputs.get("analog_output_0", 0.0)),),
    "standard_analog_output1": lambda t: (float(t.ctl.inputs.get("analog_output_1", 0.0)),),
    "payload": lambda t: (float(t.payload[0]),),
    "payload_cog": lambda t: [float(x) for x in t.payload[1:4]],
    "output_bit_registers0_to_31": lambda t: (t.ctl.output_bits & 0xFFFFFFFF,),
    "output_bit_registers32_to_63": lambda t: ((t.ctl.output_bits >> 32) & 0xFFFFFFFF,),
}


def _register(side: str, kind: str, x: int) -> Reader:
    if side == "input":
        name = f"input_{kind}_register_{x}"
        zero: Any = {"int": 0, "double": 0.0, "bit": False}[kind]
        return lambda t: (t.ctl.inputs.get(name, zero),)
    if kind == "int":
        return lambda t: (t.ctl.output_int[x],)
    if kind == "double":
        return lambda t: (t.ctl.output_double[x],)
    return lambda t: (bool((t.ctl.output_bits >> x) & 1),)


def reader(name: str, kind: str) -> Reader:
    """How to read output `name` of type `kind` (a known name; see rtde_variables)."""
    if name in READERS:
        return READERS[name]
    reg = rv.register(name)
    if reg is not None:
        return _register(*reg)
    if name in rv.INPUTS:  # an input read back: what the last client wrote
        zero = (0.0 if "D" in kind else 0,) * rv.COUNTS[kind]
        return lambda t: (
            t.ctl.inputs.get(name, zero)
            if rv.COUNTS[kind] > 1
            else (t.ctl.inputs.get(name, zero[0]),)
        )
    zeros = _zeros(kind)  # not simulated: 0 (the guide)
    return lambda t: zeros


def _zeros(kind: str) -> tuple[Any, ...]:
    return (0.0 if "D" in kind else 0,) * rv.COUNTS[kind]


def _unsimulated(name: str) -> bool:
    """An output armfleet has no source for (always zeros: `reader`'s last case)."""
    return name not in READERS and rv.register(name) is None and name not in rv.INPUTS


def _output_run(names: Sequence[str], i: int) -> tuple[str, int, int] | None:
    """The run of output int/double registers with consecutive numbers starting at
    names[i]: (kind, first number, length), None when names[i] is not one."""
    reg = rv.register(names[i])
    if reg is None or reg[0] != "output" or reg[1] == "bit":
        return None
    _, kind, x = reg
    n = 1
    while i + n < len(names) and rv.register(names[i + n]) == ("output", kind, x + n):
        n += 1
    return kind, x, n


def readers(names: Sequence[str], kinds: Sequence[str]) -> tuple[Reader, ...]:
    """The readers of a recipe, in order, with runs merged into one reader each: output
    registers of one kind numbered one after the other (a slice of the controller's list),
    and outputs with no source (their zeros as one tuple). Why: packing calls every reader
    once per package, and ur_rtde's recipes ask for such runs (its receive interface: 58
    outputs, 16 of them registers 12-19, 14 never simulated), so a pack of them cost
    as much in calls as in values."""
    out: list[Reader] = []
    i = 0
    while i < len(names):
        run = _output_run(names, i)
        if run is not None and run[2] > 1:
            kind, x, n = run
            if kind == "int":
                out.append(lambda t, a=x, b=x + n: t.ctl.output_int[a:b])
            else:
                out.append(lambda t, a=x, b=x + n: t.ctl.output_double[a:b])
            i += n
            continue
        if _unsimulated(names[i]):
            zeros: tuple[Any, ...] = ()
            while i < len(names) and _unsimulated(names[i]):
                zeros += _zeros(kinds[i])
                i += 1
            out.append(lambda t, z=zeros: z)
            continue
        out.append(reader(names[i], kinds[i]))
        i += 1
    return tuple(out)


@dataclass(frozen=True)
class OutputRecipe:
    """A client's output recipe: its id, names, types, layout and readers."""

    id: int
    names: tuple[str, ...]
    types: tuple[str, ...]
    layout: struct.Struct
    readers: tuple[Reader, ...]
    frequency: float

    @classmethod
    def build(cls, recipe_id: int, names: list[str], frequency: float) -> OutputRecipe:
        types = [rv.output_type(n) for n in names]
        return cls(
            recipe_id,
            tuple(names),
            tuple(types),
            rv.struct_of(["UINT8", *types]),
            readers(names, types),
            frequency,
        )

    def pack(self, t: WorldTick) -> bytes:
        values: list[Any] = [self.id]
        extend = values.extend
        for read in self.readers:
            extend(read(t))
        return self.layout.pack(*values)


def apply_inputs(ctl: Controller, names: Sequence[str], values: Sequence[Any]) -> None:
    """Keep what an input data package wrote (per world), and what the robot does with the
    IO ones: the speed slider, the standard digital and analog outputs."""
    sent = dict(zip(names, values, strict=True))
    ctl.inputs.update(sent)
    inputs = ctl.inputs
    if "speed_slider_fraction" in sent and int(inputs.get("speed_slider_mask", 0)) & 1:
        fraction = float(sent["speed_slider_fraction"])
        if math.isfinite(fraction):
            ctl.speed_fraction = min(1.0, max(0.0, fraction))
    mask = int(inputs.get("standard_digital_output_mask", 0))
    if "standard_digital_output" in sent and mask:
        bits = int(inputs.get("digital_outputs", 0))
        bits = (bits & ~mask) | (int(sent["standard_digital_output"]) & mask)
        inputs["digital_outputs"] = bits
    amask = int(inputs.get("standard_analog_output_mask", 0))
    for i in (0, 1):
        key = f"standard_analog_output_{i}"
        if key in sent and amask & (1 << i):
            inputs[f"analog_output_{i}"] = float(sent[key])
    ctl.changed()
