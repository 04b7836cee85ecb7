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

Why values are computed lazily per (world, tick): a 500 Hz stream of a 60 Hz world sends the
same tick several times, and most recipes ask for a few of these.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from service.core.sim.types import Snapshot
from service.surfaces.ur import rtde_variables as rv
from service.surfaces.ur.controller import Controller
from service.surfaces.ur.tcp_pose import ARM, ToolKinematics


@dataclass(frozen=True)
class Frame:
    """What the sink hands RTDE after a tick (built on the sim thread): the snapshot, the
    target's rate of change (nworld, 7), and the tick length [s]."""

    snap: Snapshot
    target_qd: np.ndarray
    target_qdd: np.ndarray
    tick_dt: float


class WorldTick:
    """One world's values at one frame's tick, each computed when first read."""

    def __init__(
        self,
        frame: Frame,
        world: int,
        kin: ToolKinematics,
        ctl: Controller,
        payload: Sequence[float],
        tcp_offset: Sequence[float] = (0.0,) * 6,
    ):
        self.frame, self.w, self.kin, self.ctl, self.payload = frame, world, kin, ctl, payload
        self.tcp_offset = tuple(float(x) for x in tcp_offset)

    def _row(self, a: np.ndarray) -> list[float]:
        return [float(x) for x in a[self.w, :ARM]]

    @cached_property
    def q(self) -> list[float]:
        return self._row(self.frame.snap.position)

    @cached_property
    def qd(self) -> list[float]:
        return self._row(self.frame.snap.velocity)

    @cached_property
    def effort(self) -> list[float]:
        return self._row(self.frame.snap.effort)

    @cached_property
    def target(self) -> list[float]:
        return self._row(self.frame.snap.target)

    @cached_property
    def target_qd(self) -> list[float]:
        return self._row(self.frame.target_qd)

    @cached_property
    def target_qdd(self) -> list[float]:
        return self._row(self.frame.target_qdd)

    @cached_property
    def _actual_tcp(self) -> tuple[np.ndarray, np.ndarray]:
        return self.kin.tcp(np.array(self.q), np.array(self.qd), self.tcp_offset)

    @cached_property
    def _target_tcp(self) -> tuple[np.ndarray, np.ndarray]:
        return self.kin.tcp(np.array(self.target), np.array(self.target_qd), self.tcp_offset)


_ZERO6, _ZERO3 = (0.0,) * 6, (0.0,) * 3
Reader = Callable[[WorldTick], Sequence[Any]]


def _tcp(which: str, part: int) -> Reader:
    return lambda t: getattr(t, which)[part].tolist()


READERS: dict[str, Reader] = {
    "timestamp": lambda t: (t.frame.snap.tick * t.frame.tick_dt,),
    "actual_q": lambda t: t.q,
    "actual_qd": lambda t: t.qd,
    "actual_current": lambda t: t.effort,
    "target_current": lambda t: t.effort,
    "target_moment": lambda t: t.effort,
    "target_q": lambda t: t.target,
    "target_qd": lambda t: t.target_qd,
    "target_qdd": lambda t: t.target_qdd,
    "actual_TCP_pose": _tcp("_actual_tcp", 0),
    "actual_TCP_speed": _tcp("_actual_tcp", 1),
    "target_TCP_pose": _tcp("_target_tcp", 0),
    "target_TCP_speed": _tcp("_target_tcp", 1),
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
    zeros = (0.0 if "D" in kind else 0,) * rv.COUNTS[kind]  # not simulated: 0 (the guide)
    return lambda t: zeros


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
            tuple(reader(n, k) for n, k in zip(names, types, strict=True)),
            frequency,
        )

    def pack(self, t: WorldTick) -> bytes:
        values: list[Any] = [self.id]
        for read in self.readers:
            values.extend(read(t))
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
