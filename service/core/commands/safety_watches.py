"""Every world's safety system, started in one call: the watches that raise protective stops.

Why one call: the service starts the robot's safety system as a whole, on every world, before
the first tick; which rules it holds is this package's business, not the runtime's. The rules:
a commanded target into a fixed obstacle (clearance_watch.py) and an arm joint held at its
torque limit (torque_watch.py). A user's trigger and the unlock are commands (safety_stop.py).
"""

from __future__ import annotations

from service.core.commands.clearance_watch import ClearanceWatch, watch_clearance
from service.core.commands.control import Control
from service.core.commands.torque_watch import TorqueWatch, watch_torque

__all__ = ["watch_safety"]


def watch_safety(control: Control) -> tuple[ClearanceWatch | None, TorqueWatch]:
    """Both watches on the loop's sinks (the clearance watch None where the cell has nothing
    it could measure: its log line says why)."""
    return watch_clearance(control), watch_torque(control)
