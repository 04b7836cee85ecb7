"""ur_rtde's control script commands: number → name and the registers its arguments are in.

Read off the script ur_rtde 1.6.x uploads (`process_cmd(cmd)` in librtde.so.1.6.5's
`rtde_control` program, build 14.02.2024-12:23): the command number is input integer register 0,
its arguments input double registers 0.. and integer registers 1.., all shifted by the
script's register offset (0, or 24 with FLAG_UPPER_RANGE_REGISTERS). `decode` turns the
registers into named arguments and refuses values the robot could not carry out: not finite,
or outside the ranges ur_rtde itself checks before it sends (its `verifyValueIsWithin` bounds)
or the UR10e's (a pose within 3 m, a payload within 12.5 kg at 0.3 m). A refusal names the
command, the argument and the limit.

`SUPPORTED` are carried out (script_runner.py); `REFUSED` are commands of the same script that
armfleet does not carry out (force mode, freedrive, teach mode, contact detection, ...): the
script stops with a line naming them, as a script that fails does. `REALTIME` are those the
script processes without the done handshake (servo, speed, ...).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

SUPPORTED = {
    1: "moveJ", 2: "moveJ_IK", 3: "moveL", 4: "moveL_FK", 9: "speedJ", 10: "speedL",
    11: "servoJ", 15: "speedStop", 16: "servoStop", 17: "setPayload", 24: "servoL",
    26: "getStepTime", 29: "setTcp", 30: "getInverseKinematics", 31: "triggerProtectiveStop",
    33: "stopL", 34: "stopJ", 36: "isPoseWithinSafetyLimits", 37: "isJointsWithinSafetyLimits",
    38: "getJointTorques", 40: "getTCPOffset", 41: "jogStart", 42: "jogStop",
    43: "getForwardKinematics", 44: "getForwardKinematics", 45: "movePath",
    46: "getInverseKinematics", 47: "isSteady", 58: "getActualToolFlangePose",
    60: "getInverseKinematicsHasSolution", 61: "getInverseKinematicsHasSolution",
    255: "stopScript",
}  # fmt: skip
REFUSED = {
    6: "forceMode", 7: "forceModeStop", 8: "zeroFtSensor", 12: "servoC", 18: "teachMode",
    19: "endTeachMode", 20: "forceModeSetDamping", 21: "forceModeSetGainScaling",
    25: "toolContact", 27: "getActualJointPositionsHistory", 28: "getTargetWaypoint",
    35: "setWatchdog", 39: "poseTrans", 51: "moveUntilContact", 52: "freedriveMode",
    53: "endFreedriveMode", 54: "getFreedriveStatus", 56: "ftRtdeInputEnable",
    57: "enableExternalFtSensor", 59: "setGravity", 62: "startContactDetection",
    63: "stopContactDetection", 64: "readContactDetection", 65: "setTargetPayload",
}  # fmt: skip
# The script's own no-ops in 1.6.x (`dummy_op = 1`): done at once, as it does.
NO_OPS = {
    66: "directTorque", 67: "getMassMatrix", 68: "getCoriolisAndCentrifugalTorques",
    69: "getTargetJointAccelerations", 70: "getJacobian", 71: "getJacobianTimeDerivative",
}  # fmt: skip
REALTIME = {24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71}

# Bounds ur_rtde checks before sending (rtde_control_interface.h), the robot's own beyond them.
JOINT_SPEED = (0.0, 3.14)  # rad/s
JOINT_ACCEL = (0.0, 40.0)  # rad/s²
TOOL_SPEED = (0.0, 3.0)  # m/s
TOOL_ACCEL = (0.0, 150.0)  # m/s²
SERVO_TIME = (0.001, 1.0)  # s
LOOKAHEAD = (0.03, 0.2)  # s
GAIN = (100.0, 2000.0)
POSE_REACH = 3.0  # m
ANGLE = 4 * math.pi  # rad: joint angles and rotation vectors
PAYLOAD = (0.0, 12.5)  # kg
COG = 0.3  # m
ANY = 1e9  # m: a pose a question is asked about (the answer may be no)


class BadRegister(ValueError):
    """Registers a command cannot be carried out with (the text names what and the limit)."""


@dataclass(frozen=True)
class Registers:
    """One world's input registers as the script reads them (with its offset)."""

    inputs: Mapping[str, object]
    offset: int

    def d(self, i: int) -> float:
        return float(self.inputs.get(f"input_double_register_{i + self.offset}", 0.0))  # type: ignore[arg-type]

    def n(self, i: int) -> int:
        return int(self.inputs.get(f"input_int_register_{i + self.offset}", 0))  # type: ignore[call-overload]

    def six(self, i: int) -> list[float]:
        return [self.d(i + k) for k in range(6)]


def _finite(name: str, what: str, values: list[float], limit: float, unit: str) -> list[float]:
    for k, v in enumerate(values):
        if not math.isfinite(v):
            raise BadRegister(f"{name}: {what}[{k}] is {v} (not a finite number)")
        if abs(v) > limit:
            raise BadRegister(f"{name}: {what}[{k}] = {v:g} is outside ±{limit:g} {unit}")
    return values


def _within(name: str, what: str, v: float, bounds: tuple[float, float], unit: str) -> float:
    if not math.isfinite(v) or not bounds[0] <= v <= bounds[1]:
        raise BadRegister(f"{name}: {what} = {v} is outside [{bounds[0]:g}, {bounds[1]:g}] {unit}")
    return v


def _pose(
    name: str, values: list[float], what: str = "pose", reach: float = POSE_REACH
) -> list[float]:
    _finite(name, what, values[:3], reach, "m")
    _finite(name, what, values[3:], ANGLE, "rad")
    return values


def _tcp(name: str, values: list[float]) -> list[float]:
    _finite(name, "tcp", values[:3], 1.0, "m")
    _finite(name, "tcp", values[3:], ANGLE, "rad")
    return values


def _q(name: str, values: list[float], what: str = "q") -> list[float]:
    return _finite(name, what, values, ANGLE, "rad")


def _move(joint: bool, target: str) -> Callable[[str, Registers], dict[str, Any]]:
    speed, accel = (JOINT_SPEED, JOINT_ACCEL) if joint else (TOOL_SPEED, TOOL_ACCEL)
    unit = "rad/s" if joint else "m/s"

    def decode(name: str, r: Registers) -> dict[str, Any]:
        values = r.six(0)
        values = _q(name, values) if target == "q" else _pose(name, values)
        return {
            target: values,
            "speed": _within(name, "speed", r.d(6), speed, unit),
            "accel": _within(name, "acceleration", r.d(7), accel, unit + "²"),
            "async": r.n(1) == 1,
        }

    return decode


def _servo(target: str) -> Callable[[str, Registers], dict[str, Any]]:
    def decode(name: str, r: Registers) -> dict[str, Any]:
        values = _q(name, r.six(0)) if target == "q" else _pose(name, r.six(0))
        return {
            target: values,
            "time": _within(name, "time", r.d(8), SERVO_TIME, "s"),
            "lookahead": _within(name, "lookahead_time", r.d(9), LOOKAHEAD, "s"),
            "gain": _within(name, "gain", r.d(10), GAIN, ""),
        }

    return decode


def _speed(name: str, r: Registers) -> dict[str, Any]:
    values = _finite(name, "speed", r.six(0), 2 * math.pi, "m/s or rad/s")
    accel = _within(name, "acceleration", r.d(6), (1e-6, TOOL_ACCEL[1]), "m/s² or rad/s²")
    return {"speed": values, "accel": accel}


def _decel(name: str, r: Registers) -> dict[str, Any]:
    return {"decel": _within(name, "deceleration", r.d(0), (1e-6, 1000.0), "m/s² or rad/s²"),
            "async": r.n(1) == 1}  # fmt: skip


def _payload(name: str, r: Registers) -> dict[str, Any]:
    mass = _within(name, "mass", r.d(0), PAYLOAD, "kg")
    cog = _finite(name, "cog", [r.d(1), r.d(2), r.d(3)], COG, "m")
    return {"mass": mass, "cog": cog}


def _ik(name: str, r: Registers) -> dict[str, Any]:
    return {"pose": _pose(name, r.six(0), reach=ANY), "q_near": _q(name, r.six(6), "qnear")}


def _asked(name: str, r: Registers) -> dict[str, Any]:
    """A question about a pose (has it a solution? is it safe?): any finite pose is asked."""
    return {"pose": _pose(name, r.six(0), reach=ANY)}


def _jog(name: str, r: Registers) -> dict[str, Any]:
    speed = _finite(name, "speeds", r.six(0), 2 * math.pi, "m/s or rad/s")
    feature = r.d(6)
    if feature not in (0.0, 1.0, 2.0):
        raise BadRegister(f"{name}: feature = {feature} (0 base, 1 tool, 2 custom)")
    accel = _within(name, "acceleration", r.d(7), (1e-6, TOOL_ACCEL[1]), "m/s²")
    return {"speed": speed, "feature": int(feature), "accel": accel,
            "frame": _pose(name, r.six(8), "custom_frame")}  # fmt: skip


_NONE: Callable[[str, Registers], dict[str, Any]] = lambda name, r: {}  # noqa: E731
DECODERS: dict[int, Callable[[str, Registers], dict[str, Any]]] = {
    1: _move(True, "q"), 2: _move(True, "pose"), 3: _move(False, "pose"), 4: _move(False, "q"),
    9: _speed, 10: _speed, 11: _servo("q"), 24: _servo("pose"),
    15: _decel, 16: _decel, 33: _decel, 34: _decel, 17: _payload,
    29: lambda n, r: {"pose": _tcp(n, r.six(0))},
    30: _ik, 61: _ik, 46: lambda n, r: {"pose": _pose(n, r.six(0))},
    60: _asked, 36: _asked, 37: lambda n, r: {"q": _q(n, r.six(0))},
    41: _jog, 43: _NONE, 44: lambda n, r: {"q": _q(n, r.six(0)), "tcp": _pose(n, r.six(6), "tcp")},
    45: lambda n, r: {"async": r.n(1) == 1},
}  # fmt: skip


@dataclass(frozen=True)
class ScriptCommand:
    number: int
    name: str
    args: dict[str, Any]


def decode(number: int, regs: Registers) -> ScriptCommand:
    """The command `number` with its arguments; BadRegister for an unknown or refused command
    or a value out of range."""
    if number in NO_OPS:
        return ScriptCommand(number, NO_OPS[number], {})
    if number in REFUSED:
        raise BadRegister(f"{REFUSED[number]} (command {number}) is not carried out by armfleet")
    name = SUPPORTED.get(number)
    if name is None:
        raise BadRegister(f"command {number} is not one of the control script's")
    return ScriptCommand(number, name, DECODERS.get(number, _NONE)(name, regs))
