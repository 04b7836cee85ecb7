"""One world's UR controller state: robot mode, safety mode, program, registers and inputs.

Why one place: the Dashboard changes it (power, brakes, play, stop, unlock), RTDE reports it
(robot_mode, safety_mode, the status bits, runtime_state, the registers) and stores into it
(input recipes' values, kept per world for the control interface), and a later control
interface reads it; all of them run on the UR event loop's thread (endpoints.py), so there is
no lock. The numbers are UR's (RTDE guide, Dashboard server documentation). A world starts as
a UR10e ready to move (powered, brakes released: RUNNING, NORMAL), because its servos hold it
from the first tick; `reset` returns it there when a lease starts or ends.

The safety mode is not kept here but in the core's `SafetyTable` (core/sim/safety.py), read
and written through `safety_mode`: a protective stop is the world's state, which the REST and
WebSocket states report too, and a reset over any surface clears it. `version` counts the
table's changes of this world with the controller's own, so RTDE re-encodes on either.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from service.core.sim.safety import SafetyTable


class RobotMode(enum.IntEnum):
    NO_CONTROLLER = -1
    DISCONNECTED = 0
    CONFIRM_SAFETY = 1
    BOOTING = 2
    POWER_OFF = 3
    POWER_ON = 4
    IDLE = 5
    BACKDRIVE = 6
    RUNNING = 7
    UPDATING_FIRMWARE = 8


class SafetyMode(enum.IntEnum):
    NORMAL = 1
    REDUCED = 2
    PROTECTIVE_STOP = 3
    RECOVERY = 4
    SAFEGUARD_STOP = 5
    SYSTEM_EMERGENCY_STOP = 6
    ROBOT_EMERGENCY_STOP = 7
    VIOLATION = 8
    FAULT = 9
    VALIDATE_JOINT_ID = 10
    UNDEFINED_SAFETY_MODE = 11
    AUTOMATIC_MODE_SAFEGUARD_STOP = 12
    SYSTEM_THREE_POSITION_ENABLING_STOP = 13


class ProgramState(enum.Enum):
    """The Dashboard's programState words, with RTDE's runtime_state number."""

    STOPPED = 1
    PLAYING = 2
    PAUSED = 4


# safety_status_bits (RTDE): which bit each safety mode sets
_SAFETY_BIT = {
    SafetyMode.NORMAL: 0,
    SafetyMode.REDUCED: 1,
    SafetyMode.PROTECTIVE_STOP: 2,
    SafetyMode.RECOVERY: 3,
    SafetyMode.SAFEGUARD_STOP: 4,
    SafetyMode.SYSTEM_EMERGENCY_STOP: 5,
    SafetyMode.ROBOT_EMERGENCY_STOP: 6,
    SafetyMode.VIOLATION: 8,
    SafetyMode.FAULT: 9,
}
_EMERGENCY = {SafetyMode.SYSTEM_EMERGENCY_STOP, SafetyMode.ROBOT_EMERGENCY_STOP}
_MOVING = {SafetyMode.NORMAL, SafetyMode.REDUCED}  # the modes in which the arm may move
_SAFETY_MODES = {int(m): m for m in SafetyMode}
_STOPPED_BY_SAFETY = 10  # bit: "stopped due to safety"
JOINT_RUNNING, JOINT_IDLE, JOINT_POWER_OFF = 253, 255, 239  # joint_mode


@dataclass
class Controller:
    """One world's controller (see the module docstring). `version` counts changes, so that
    RTDE re-encodes a package only when the state or the tick moved."""

    world: int
    safety: SafetyTable = field(repr=False)  # the loop's, every world's safety mode
    robot_mode: RobotMode = RobotMode.RUNNING
    program: ProgramState = ProgramState.STOPPED
    loaded_program: str | None = None
    speed_fraction: float = 1.0  # the speed slider (RTDE input speed_slider_fraction)
    # Registers: the control script writes outputs; RTDE input recipes write inputs (any input
    # variable, by name, as the client sent it).
    output_int: list[int] = field(default_factory=lambda: [0] * 48)
    output_double: list[float] = field(default_factory=lambda: [0.0] * 48)
    output_bits: int = 0  # output_bit_register 0..127 as one integer
    inputs: dict[str, object] = field(default_factory=dict)
    edits: int = 0

    def changed(self) -> None:
        self.edits += 1

    @property
    def version(self) -> int:
        """Changes of this controller and of the world's safety mode (both only count up)."""
        return self.edits + int(self.safety.versions[self.world])

    @property
    def safety_mode(self) -> SafetyMode:
        # a dict, not SafetyMode(n): RTDE reads it several times a package (enum calls cost
        # most of packing one); ValueError for a number UR has no mode of, as SafetyMode(n)
        mode = self.safety.mode(self.world)
        try:
            return _SAFETY_MODES[mode]
        except KeyError:
            raise ValueError(f"{mode} is not a valid SafetyMode") from None

    def reset(self) -> None:
        """Back to a freshly booted, ready controller (a lease started or ended)."""
        fresh = Controller(self.world, self.safety)
        for name in self.__dataclass_fields__:
            if name not in ("world", "safety", "edits"):
                setattr(self, name, getattr(fresh, name))
        self.safety.clear([self.world])
        self.changed()

    # -- what RTDE reports ------------------------------------------------------------------

    @property
    def safety_status_bits(self) -> int:
        mode = self.safety_mode
        bits = 1 << _SAFETY_BIT.get(mode, _STOPPED_BY_SAFETY)
        if mode in _EMERGENCY:
            bits |= 1 << 7  # "is emergency stopped"
        if mode not in _MOVING:
            bits |= 1 << _STOPPED_BY_SAFETY
        return bits

    @property
    def robot_status_bits(self) -> int:
        """bit 0 power on, bit 1 program running (bits 2-3: free-drive and power buttons)."""
        powered = self.robot_mode in (RobotMode.POWER_ON, RobotMode.IDLE, RobotMode.RUNNING)
        return int(powered) | (int(self.program is ProgramState.PLAYING) << 1)

    @property
    def runtime_state(self) -> int:
        return self.program.value

    @property
    def joint_mode(self) -> int:
        if self.robot_mode is RobotMode.RUNNING:
            return JOINT_RUNNING
        return JOINT_IDLE if self.robot_mode is RobotMode.IDLE else JOINT_POWER_OFF

    @property
    def speed_scaling(self) -> float:
        """What the trajectory runs at: the slider, 0 while stopped by safety or unpowered."""
        if self.robot_mode is not RobotMode.RUNNING or self.safety_mode not in _MOVING:
            return 0.0
        return self.speed_fraction

    # -- what the Dashboard (and later the safety rules) change ------------------------------

    def power_on(self) -> None:
        if self.robot_mode in (RobotMode.POWER_OFF, RobotMode.POWER_ON):
            self.robot_mode = RobotMode.IDLE  # powered, brakes still on
            self.changed()

    def power_off(self) -> None:
        self.robot_mode = RobotMode.POWER_OFF
        self.program = ProgramState.STOPPED
        self.changed()

    def brake_release(self) -> bool:
        if self.robot_mode not in (RobotMode.IDLE, RobotMode.RUNNING):
            return False
        self.robot_mode = RobotMode.RUNNING
        self.changed()
        return True

    def stopped(self) -> None:
        """The world was protective-stopped (its mode is the core's SafetyTable): the program
        is STOPPED."""
        self.program = ProgramState.STOPPED
        self.changed()

    def unlock_protective_stop(self) -> bool:
        """False while the stop is younger than safety.UNLOCK_AFTER_S (the robot's rule)."""
        return self.safety.unlock(self.world)

    def restart_safety(self) -> None:
        """The Dashboard's `restart safety`: NORMAL at once, the arm powered off."""
        self.safety.clear([self.world])
        self.power_off()

    def set_program(self, state: ProgramState) -> None:
        self.program = state
        self.changed()

    def can_run_script(self) -> bool:
        """A program sent to a script port runs only on a ready robot (RUNNING, not stopped)."""
        return self.robot_mode is RobotMode.RUNNING and self.safety_mode in (
            SafetyMode.NORMAL,
            SafetyMode.REDUCED,
        )

    def can_play(self) -> bool:
        return (
            self.loaded_program is not None
            and self.robot_mode is RobotMode.RUNNING
            and self.safety_mode in (SafetyMode.NORMAL, SafetyMode.REDUCED)
        )
