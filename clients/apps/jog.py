"""The pendant's jog block the controllers share: six axes, a step size and a frame.

A UR pendant jogs the tool in small steps along (X, Y, Z) and about (Rx, Ry, Rz) the axes of
the robot's base or of the tool. `JogPad` holds what the block shows and what a press sends
(`POST /v1/worlds/{w}/jog`, `clients.cartesian`): plain Python, no widgets, no I/O, so the Tk
window and the terminal app show the same texts and send the same steps, and both are tested
without a display (tests/test_controller_model.py). The browser page mirrors these presets in
service/web/js/panel.js.
"""

from __future__ import annotations

from dataclasses import dataclass

from clients.cartesian import AXES

FRAMES = ("base", "tool")
# (metres, radians) per press, fine to coarse; every one within the server's ±0.1 per step.
STEPS: tuple[tuple[float, float], ...] = ((0.001, 0.01), (0.01, 0.05), (0.05, 0.1))
DEFAULT_STEP = 1  # 10 mm / 0.05 rad


def axis_name(axis: str) -> str:
    """How the pendant writes an axis: X, Y, Z, Rx, Ry, Rz."""
    return axis.upper() if len(axis) == 1 else axis.capitalize()


def button_text(axis: str, sign: int) -> str:
    """The text of a jog button: `+Z`, `-Rx`."""
    return f"{'+' if sign > 0 else '-'}{axis_name(axis)}"


def step_text(index: int) -> str:
    """A step preset as the controls list it: `10 mm / 0.05 rad`."""
    metres, radians = STEPS[index]
    return f"{metres * 1000:g} mm / {radians:g} rad"


@dataclass
class JogPad:
    """What the jog block is set to: the frame its steps are in and the step preset."""

    frame: str = "base"
    step_index: int = DEFAULT_STEP

    def step(self, axis: str, sign: int) -> float:
        """The signed step of one press on `axis`: metres for x y z, radians for rx ry rz."""
        if axis not in AXES:
            raise ValueError(f"axis is one of {AXES}, got {axis!r}")
        metres, radians = STEPS[self.step_index]
        size = metres if len(axis) == 1 else radians
        return size if sign > 0 else -size

    def toggle_frame(self) -> str:
        self.frame = "tool" if self.frame == "base" else "base"
        return self.frame

    def set_frame(self, frame: str) -> None:
        if frame not in FRAMES:
            raise ValueError(f"frame is one of {FRAMES}, got {frame!r}")
        self.frame = frame

    def cycle_step(self, by: int = 1) -> int:
        """The next (or previous) preset, wrapping around."""
        self.step_index = (self.step_index + by) % len(STEPS)
        return self.step_index

    def set_step_text(self, text: str) -> None:
        """Pick the preset a control shows as `text` (one of `step_texts()`)."""
        self.step_index = step_texts().index(text)

    def row_label(self, axis: str) -> str:
        unit = "m" if len(axis) == 1 else "rad"
        return f"jog {axis_name(axis)} [{unit}]"

    def row_step_text(self, axis: str) -> str:
        return f"±{self.step(axis, 1):g}"

    def summary(self) -> str:
        return f"Jog: {self.frame} frame, step {step_text(self.step_index)}"


def step_texts() -> list[str]:
    return [step_text(i) for i in range(len(STEPS))]
