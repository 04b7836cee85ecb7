"""RTDE's variable names and types (UR's RTDE guide, e-Series 5.x): what a recipe may ask.

A name outside these tables is answered `NOT_FOUND` in the recipe's type list, as the robot
does. Registers are names with a number: `output_int_register_X` and `output_double_register_X`
(X 0..47), `output_bit_register_X` (64..127), the same for `input_*`.
"""

from __future__ import annotations

import re
import struct

NOT_FOUND, IN_USE = "NOT_FOUND", "IN_USE"
# type → struct codes of its value(s)
CODES = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}
SIZES = {t: struct.calcsize(">" + c) for t, c in CODES.items()}
COUNTS = {t: len(struct.unpack(">" + c, bytes(SIZES[t]))) for t, c in CODES.items()}

_V6, _V3, _D = "VECTOR6D", "VECTOR3D", "DOUBLE"
OUTPUTS: dict[str, str] = {
    "timestamp": _D,
    **dict.fromkeys(
        (
            "target_q",
            "target_qd",
            "target_qdd",
            "target_current",
            "target_moment",
            "actual_q",
            "actual_qd",
            "actual_current",
            "actual_current_window",
            "joint_control_output",
            "actual_TCP_pose",
            "actual_TCP_speed",
            "actual_TCP_force",
            "target_TCP_pose",
            "target_TCP_speed",
            "joint_temperatures",
            "actual_joint_voltage",
            "ft_raw_wrench",
            "payload_inertia",
        ),
        _V6,
    ),
    "actual_digital_input_bits": "UINT64",
    "actual_digital_output_bits": "UINT64",
    "actual_execution_time": _D,
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": _V3,
    "elbow_position": _V3,
    "elbow_velocity": _V3,
    "payload_cog": _V3,
    **dict.fromkeys(
        (
            "speed_scaling",
            "target_speed_fraction",
            "actual_momentum",
            "actual_main_voltage",
            "actual_robot_voltage",
            "actual_robot_current",
            "standard_analog_input0",
            "standard_analog_input1",
            "standard_analog_output0",
            "standard_analog_output1",
            "io_current",
            "euromap67_24V_voltage",
            "euromap67_24V_current",
            "tool_analog_input0",
            "tool_analog_input1",
            "tool_output_current",
            "tool_temperature",
            "tcp_force_scalar",
            "payload",
            "joint_position_deviation_ratio",
            "collision_detection_ratio",
        ),
        _D,
    ),
    **dict.fromkeys(
        (
            "runtime_state",
            "robot_status_bits",
            "safety_status_bits",
            "analog_io_types",
            "euromap67_input_bits",
            "euromap67_output_bits",
            "tool_mode",
            "tool_analog_input_types",
            "output_bit_registers0_to_31",
            "output_bit_registers32_to_63",
            "input_bit_registers0_to_31",
            "input_bit_registers32_to_63",
            "script_control_line",
            "time_scale_source",
        ),
        "UINT32",
    ),
    "tool_output_voltage": "INT32",
    "tool_output_mode": "UINT8",
    "tool_digital_output0_mode": "UINT8",
    "tool_digital_output1_mode": "UINT8",
}
INPUTS: dict[str, str] = {
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": _D,
    **dict.fromkeys(
        (
            "standard_digital_output_mask",
            "standard_digital_output",
            "configurable_digital_output_mask",
            "configurable_digital_output",
            "tool_digital_output_mask",
            "tool_digital_output",
            "standard_analog_output_mask",
            "standard_analog_output_type",
        ),
        "UINT8",
    ),
    "standard_analog_output_0": _D,
    "standard_analog_output_1": _D,
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": _V6,
}
_REGISTER = re.compile(r"(input|output)_(int|double|bit)_register_(\d{1,3})")
_REGISTER_TYPE = {"int": "INT32", "double": _D, "bit": "BOOL"}


def register(name: str) -> tuple[str, str, int] | None:
    """("input"|"output", "int"|"double"|"bit", X) of a register name in range, else None."""
    m = _REGISTER.fullmatch(name)
    if m is None:
        return None
    side, kind, x = m.group(1), m.group(2), int(m.group(3))
    ok = 64 <= x <= 127 if kind == "bit" else 0 <= x <= 47
    return (side, kind, x) if ok else None


def output_type(name: str) -> str:
    """An output recipe's type of `name` (inputs can be read back as outputs)."""
    reg = register(name)
    if reg is not None:
        return _REGISTER_TYPE[reg[1]]
    return OUTPUTS.get(name) or INPUTS.get(name) or NOT_FOUND


def input_type(name: str) -> str:
    reg = register(name)
    if reg is not None:
        return _REGISTER_TYPE[reg[1]] if reg[0] == "input" else NOT_FOUND
    return INPUTS.get(name, NOT_FOUND)


def struct_of(types: list[str]) -> struct.Struct:
    """The big-endian layout of one data package's values (after its recipe id)."""
    return struct.Struct(">" + "".join(CODES[t] for t in types))
