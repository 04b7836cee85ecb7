"""The WebSocket ops of trajectories (`trajectory`, `cancel_trajectory`), for Control.handle.

`{"op": "trajectory", "id": 7, "world": 0, "joint_names": [...], "points": [...]}` (the body of
POST /v1/worlds/{w}/trajectory) is acked with the trajectory's id and ticks;
`{"op": "cancel_trajectory", "id": 8, "world": 0}` with the stopped trajectory's status (null
when none was running). Errors are the usual error frames, raised by the caller's handler.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from service.core.errors import BadCommand
from service.core.loop import SimLoop
from service.core.trajectory.schemas import TrajectoryBody
from service.core.trajectory.spec import JointTrajectorySpec, parse
from service.core.trajectory.status import Started, TrajectoryStatus
from service.core.types import RobotSpec


class Control(Protocol):
    """What these ops need of `Control` (control.py imports this module, not the reverse)."""

    spec: RobotSpec
    loop: SimLoop

    def start_trajectory(
        self, worlds: Sequence[int], spec: JointTrajectorySpec, source: Any
    ) -> list[Started]: ...

    def cancel_trajectory(self, worlds: Sequence[int], source: Any) -> list[TrajectoryStatus]: ...


OPS = ("cancel_trajectory", "trajectory")


def handle(
    control: Control, op: str, msg_id: Any, world: int, body: dict[str, Any], source: str
) -> dict[str, Any]:
    """Run one trajectory op; the ack frame (ValidationError / ArmfleetError propagate)."""
    if op == "trajectory":
        spec = parse(control.spec, TrajectoryBody.model_validate(body).as_json())
        started = control.start_trajectory([world], spec, source)[0]
        return {
            "op": "ack",
            "id": msg_id,
            "world": world,
            "tick": started.start_tick,
            "trajectory": started.as_json(),
        }
    if body:
        raise BadCommand(
            next(iter(body)), "cancel_trajectory takes no fields besides op, id, world"
        )
    stopped = control.cancel_trajectory([world], source)
    status = stopped[0] if stopped else None
    tick = status.finished_tick + 1 if status and status.finished_tick is not None else None
    return {
        "op": "ack",
        "id": msg_id,
        "world": world,
        "tick": control.loop.tick + 1 if tick is None else tick,
        "trajectory": None if status is None else status.as_json(),
    }
