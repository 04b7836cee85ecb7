"""Control: the one door through which every surface commands a world.

HTTP routes, WebSocket messages, the browser page, the ROS node, rosbridge, Foxglove and replay
all run commands here (`run`, or the short forms below); none of them talks to the loop's
command tables directly. A command object is valid by construction (service.core.commands), so
a rejected command changes nothing; `run` stages it in order with every other and announces
every accepted one to the listeners (metrics, the recorder) with its source, kind, worlds,
resulting targets, effective tick and record fields.

Who may run a command is checked here too, once for every surface: a surface that knows its
caller runs commands through `acting_for(caller)`, and `run` asks the `gate`
(service.core.access.callers.Gate) about the worlds the command touches before staging it.
So is the safety mode: a command that moves the arm (`Command.moves`) of a protective-stopped
world is refused (409, core/sim/safety.py) whichever surface sent it.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

from service.core.access.callers import Caller, Gate
from service.core.commands.base import REPLAY, Accepted, Command, Door
from service.core.commands.targets import Increment, SetMany, SetTargets
from service.core.commands.trajectory import JointTrajectorySpec, Started, TrajectoryStatus
from service.core.commands.trajectory.commands import (
    CancelTrajectory,
    ResumeTrajectory,
    StartTrajectory,
)
from service.core.commands.trajectory.manager import TrajectoryManager
from service.core.commands.trajectory.status import Resumable
from service.core.commands.world import Reset, ResetResult, SetMode
from service.core.sim import rules
from service.core.sim.loop import SimLoop
from service.core.sim.loop_types import CommandResult
from service.core.sim.types import Mode

log = logging.getLogger("armfleet.control")

R = TypeVar("R")
Listener = Callable[[Accepted], None]

__all__ = ["Accepted", "Control", "Listener", "ResetResult"]


class Control(Door):
    """Stage and announce commands for a SimLoop; thread-safe like the loop itself."""

    def __init__(self, loop: SimLoop) -> None:
        super().__init__(loop, TrajectoryManager(loop))
        self._listeners: tuple[Listener, ...] = ()
        # Staging and announcing happen under one lock so that listeners hear commands in the
        # order the loop staged them (a recording replays them in that order).
        self._order = threading.Lock()
        self.gate: Gate | None = None  # set when the service lends worlds (callers.Gate)

    def add_listener(self, listener: Listener) -> None:
        """Call `listener(Accepted)` after every accepted command, on the caller's thread."""
        self._listeners = (*self._listeners, listener)

    def remove_listener(self, listener: Listener) -> None:
        self._listeners = tuple(x for x in self._listeners if x is not listener)

    def acting_for(self, caller: Caller | None) -> Control:
        """This Control as `caller` sees it: every command it runs is checked for `caller`
        (None: the service itself, unchecked: replay, lease resets)."""
        return self if caller is None else _Acting(self, caller)

    def run(self, command: Command[R], source: str, caller: Caller | None = None) -> R:
        """Stage `command` in order with every other and tell the listeners; its result.
        With a `caller`, Forbidden (403, nothing staged) unless it may touch those worlds."""
        with self._ordered():
            if caller is not None and self.gate is not None:
                self.gate.check(caller, command.touches, source)
            if command.moves and source != REPLAY:  # a recording replays what was accepted
                self.loop.safety.refuse_if_stopped(command.touches)
            result = command.stage(self, source)
            if self._listeners:
                said = command.announce(self, result)
                if said is not None:
                    kind = command.kind
                    self._announce(
                        Accepted(source, kind, said.worlds, said.targets, said.tick, said.record)
                    )
        return result

    @contextlib.contextmanager
    def _ordered(self) -> Iterator[None]:
        """Stage and announce under the order lock; then, with no lock held, tell trajectory
        listeners and waiters about trajectories the command stopped (override, reset, ...)."""
        with self._order:
            yield
        self.trajectories.dispatch()

    def _announce(self, accepted: Accepted) -> None:
        for listener in self._listeners:
            try:
                listener(accepted)
            except Exception:  # an observer must never cost the caller its reply
                log.exception("command listener %r failed", listener)

    # -- short forms of `run` for the common commands ---------------------------------------

    def world(self, world: object) -> int:
        """A world id as an int, or UnknownWorld / BadCommand naming what is wrong."""
        return rules.world_id(world, self.nworld)

    def worlds(self, worlds: Sequence[object]) -> list[int]:
        """Several world ids; every unknown one is named in one 404."""
        return rules.world_ids(worlds, self.nworld)

    def increment(
        self, world: int, deltas: Mapping[str | int, float], source: str, field: str = "deltas"
    ) -> CommandResult:
        """Add to the named joints' latest targets (the seed's Up/Down), clamped to range."""
        return self.run(Increment.create(self, world, deltas, field), source)

    def command_targets(self, world: int, name: Any, position: Any, source: str) -> CommandResult:
        """JointState-shaped targets: the named joints move, the others keep their targets."""
        return self.run(SetTargets.create(self, world, name, position), source)

    def set_many(
        self,
        worlds: Sequence[int],
        positions: Sequence[Sequence[float]] | np.ndarray,
        source: str,
        joints: Sequence[int] | None = None,
    ) -> list[CommandResult]:
        """Full 7-joint targets for many worlds, staged together for one tick boundary."""
        return self.run(SetMany.create(self, worlds, positions, joints), source)

    def reset(self, worlds: Sequence[int] | None, source: str) -> ResetResult:
        """Send worlds (all when None) back to `home`, state and targets."""
        return self.run(Reset.create(self, worlds), source)

    def set_mode(self, mode: Mode, source: str) -> int:
        """Switch realtime / fast / paused; returns the tick at which the switch happened."""
        return self.run(SetMode(Mode(mode)), source)

    def start_trajectory(
        self, worlds: Sequence[int], spec: JointTrajectorySpec, source: str
    ) -> list[Started]:
        """Run a validated trajectory on every world of `worlds` from one tick (see trajectory)."""
        return self.run(StartTrajectory.create(self, worlds, spec), source)

    def cancel_trajectory(self, worlds: Sequence[int], source: str) -> list[TrajectoryStatus]:
        """Stop the worlds' running trajectories; they hold where they were. Those stopped."""
        return self.run(CancelTrajectory.create(self, worlds), source)

    def resume_trajectory(self, run: Resumable, source: str) -> Started:
        """Put back a trajectory that ran when a recording started (replay; see Resumable)."""
        rules.world_id(run.world, self.nworld)
        return self.run(ResumeTrajectory(run), source)[0]


class _Acting(Control):
    """A Control that runs every command for one caller (`Control.acting_for`); it shares
    everything else (loop, trajectories, listeners, the order lock) with the one it wraps."""

    def __init__(self, control: Control, caller: Caller) -> None:  # no super(): shares state
        self._of = control
        self.caller = caller
        self.loop = control.loop
        self.trajectories = control.trajectories

    @property  # type: ignore[override]
    def gate(self) -> Gate | None:
        return self._of.gate

    def add_listener(self, listener: Listener) -> None:
        self._of.add_listener(listener)

    def remove_listener(self, listener: Listener) -> None:
        self._of.remove_listener(listener)

    def run(self, command: Command[R], source: str, caller: Caller | None = None) -> R:
        return self._of.run(command, source, caller or self.caller)
