"""Control: the one door through which every surface commands a world.

HTTP routes, WebSocket messages, the browser page, ROS 2, rosbridge, Foxglove and replay all call
these methods; none of them talks to the loop's command methods directly. Here a command is
validated completely (world ids, joint names, lengths, finiteness) before anything is staged, so
a rejected command changes nothing, and every accepted one is announced to the listeners (metrics,
the recorder) with its source, kind, worlds, resulting targets and effective tick.
"""

from __future__ import annotations

import contextlib
import enum
import logging
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import ValidationError

from service.core import wire
from service.core.commands import resolve_joints
from service.core.errors import ArmfleetError, BadCommand, UnknownWorld
from service.core.loop import CommandResult, SimLoop
from service.core.schemas import IncrementRequest, JointTargets
from service.core.trajectory import JointTrajectorySpec, Started, TrajectoryStatus
from service.core.trajectory import ops as trajectory_ops
from service.core.trajectory.manager import TrajectoryManager
from service.core.trajectory.status import Resumable
from service.core.types import Mode, RobotSpec

log = logging.getLogger("armfleet.control")


class Source(enum.StrEnum):
    """Where a command came from, so that metrics and recordings can tell them apart."""

    HTTP = "http"
    WS = "ws"
    BROWSER = "browser"
    ROS2 = "ros2"
    ROSBRIDGE = "rosbridge"
    FOXGLOVE = "foxglove"
    REPLAY = "replay"


@dataclass(frozen=True)
class Accepted:
    """One accepted command as the listeners see it.

    source: the surface it came through
    kind: "increment", "set_targets", "reset", "mode", "trajectory" or "trajectory_cancel"
    worlds: the worlds it changed                                   (k,) int64
    targets: those worlds' targets after it [rad]                   (k, 7) float64
        (a trajectory's: the targets it starts from / holds after the cancel)
    tick: the first tick stepped with it
    mode: the new mode (kind "mode" only)
    trajectory: the trajectory as JSON (`JointTrajectorySpec.to_json`, kind "trajectory" only)
    joints: the joint indices a target command named (None: all): a trajectory stops only if
        it drives one of them, so a replay must name the same ones
    """

    source: Source
    kind: str
    worlds: np.ndarray
    targets: np.ndarray
    tick: int
    mode: Mode | None = None
    trajectory: dict[str, Any] | None = None
    joints: tuple[int, ...] | None = None


@dataclass(frozen=True)
class ResetResult:
    """Worlds sent back to `home`, their targets afterwards (k, 7), and the effective tick."""

    worlds: list[int]
    tick: int
    targets: np.ndarray = field(repr=False)


Listener = Callable[[Accepted], None]


class Control:
    """Validate, stage and announce commands for a SimLoop; thread-safe like the loop itself."""

    def __init__(self, loop: SimLoop) -> None:
        self.loop = loop
        self._listeners: tuple[Listener, ...] = ()
        # Staging and announcing happen under one lock so that listeners hear commands in the
        # order the loop staged them (a recording replays them in that order).
        self._order = threading.Lock()
        self.trajectories = TrajectoryManager(loop)

    @property
    def spec(self) -> RobotSpec:
        return self.loop.spec

    @property
    def nworld(self) -> int:
        return self.loop.batch.nworld

    def add_listener(self, listener: Listener) -> None:
        """Call `listener(Accepted)` after every accepted command, on the caller's thread."""
        self._listeners = (*self._listeners, listener)

    def remove_listener(self, listener: Listener) -> None:
        self._listeners = tuple(x for x in self._listeners if x is not listener)

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

    # -- validation ------------------------------------------------------------------------

    def world(self, world: object) -> int:
        """A world id as an int, or UnknownWorld / BadCommand naming what is wrong."""
        if isinstance(world, bool) or not isinstance(world, int | np.integer):
            raise BadCommand("world", f"a world id must be an integer, got {world!r}")
        if not 0 <= world < self.nworld:
            raise UnknownWorld(int(world), self.nworld)
        return int(world)

    def worlds(self, worlds: Sequence[object]) -> list[int]:
        """Several world ids; every unknown one is named in one 404."""
        for w in worlds:
            if isinstance(w, bool) or not isinstance(w, int | np.integer):
                raise BadCommand("worlds", f"world ids must be integers, got {w!r}")
        missing = [int(w) for w in worlds if not 0 <= w < self.nworld]  # type: ignore[operator]
        if missing:
            raise UnknownWorld(missing, self.nworld)
        return [int(w) for w in worlds]  # type: ignore[call-overload]

    # -- commands --------------------------------------------------------------------------

    def increment(
        self,
        world: int,
        deltas: Mapping[str | int, float],
        source: Source,
        field: str = "deltas",
    ) -> CommandResult:
        """Add to the named joints' latest targets (the seed's Up/Down), clamped to range."""
        world = self.world(world)
        values = resolve_joints(self.spec, deltas, field)
        return self._stage_one("increment", source, self.loop.increment, world, values)

    def command_targets(
        self,
        world: int,
        name: Sequence[str | int],
        position: Sequence[float],
        source: Source,
    ) -> CommandResult:
        """JointState-shaped targets: the named joints move, the others keep their targets."""
        world = self.world(world)
        if len(name) != len(position):
            raise BadCommand(
                "position",
                f"name and position must have equal lengths ({len(name)} names, "
                f"{len(position)} positions)",
            )
        if len(set(name)) != len(name):
            raise BadCommand("name", "a joint may be named only once")
        values = resolve_joints(self.spec, dict(zip(name, position, strict=True)), "name")
        return self._stage_one("set_targets", source, self.loop.stage_targets, world, values)

    def set_many(
        self,
        worlds: Sequence[int],
        positions: Sequence[Sequence[float]] | np.ndarray,
        source: Source,
        joints: Sequence[int] | None = None,
    ) -> list[CommandResult]:
        """Full 7-joint targets for many worlds, staged together for one tick boundary; with
        `joints` (indices, a replay's) only those joints of each row change."""
        ids = self.worlds(worlds)
        njoint = len(self.spec.joints)
        try:
            rows = np.asarray(positions, dtype=np.float64)
        except (TypeError, ValueError):
            raise BadCommand("position", "position must be a list of rows of numbers") from None
        if rows.shape != (len(ids), njoint):
            raise BadCommand(
                "position",
                f"need one row of {njoint} targets per world: shape is {rows.shape}, "
                f"expected ({len(ids)}, {njoint})",
            )
        if not np.isfinite(rows).all():
            raise BadCommand("position", "values must be finite (no NaN or Inf)")
        with self._ordered():
            named = None if joints is None else tuple(int(j) for j in joints)
            results = self.loop.set_many(ids, rows, None if named is None else list(named))
            if results:
                self._announce(
                    Accepted(
                        source,
                        "set_targets",
                        np.array(ids, dtype=np.int64),
                        np.stack([r.target for r in results]),
                        results[0].tick,
                        joints=named,
                    )
                )
        return results

    def reset(self, worlds: Sequence[int] | None, source: Source) -> ResetResult:
        """Send worlds (all when None) back to `home`, state and targets."""
        ids = list(range(self.nworld)) if worlds is None else self.worlds(worlds)
        targets = np.tile(self.loop.batch.home_target, (len(ids), 1))
        with self._ordered():
            tick = self.loop.reset(ids)
            self._announce(Accepted(source, "reset", np.array(ids, dtype=np.int64), targets, tick))
        return ResetResult(ids, tick, targets)

    def set_mode(self, mode: Mode, source: Source) -> int:
        """Switch realtime / fast / paused; returns the tick at which the switch happened."""
        empty = np.zeros(0, dtype=np.int64)
        with self._order:
            self.loop.set_mode(mode)
            tick = self.loop.tick
            self._announce(Accepted(source, "mode", empty, np.zeros((0, 7)), tick, Mode(mode)))
        return tick

    def start_trajectory(
        self, worlds: Sequence[int], spec: JointTrajectorySpec, source: Source
    ) -> list[Started]:
        """Run a validated trajectory on every world of `worlds` from one tick (see trajectory)."""
        ids = self.worlds(worlds)
        with self._ordered():
            started = self.trajectories.start(ids, spec, source, dispatch=False)
            if started and self._listeners:
                rows = self.loop.pending_targets(np.array(ids))
                tick = started[0].start_tick
                w = np.array(ids, dtype=np.int64)
                self._announce(Accepted(source, "trajectory", w, rows, tick, None, spec.to_json()))
        return started

    def cancel_trajectory(self, worlds: Sequence[int], source: Source) -> list[TrajectoryStatus]:
        """Stop the worlds' running trajectories; they hold where they were. Those stopped."""
        ids = self.worlds(worlds)
        with self._ordered():
            stopped = self.trajectories.cancel(ids, dispatch=False)
            if stopped and self._listeners:
                w = np.array([s.world for s in stopped], dtype=np.int64)
                tick = int(stopped[0].finished_tick or 0) + 1  # the hold starts here
                self._announce(
                    Accepted(source, "trajectory_cancel", w, self.loop.pending_targets(w), tick)
                )
        return stopped

    def resume_trajectory(self, run: Resumable, source: Source) -> Started:
        """Put back a trajectory that ran when a recording started (replay; see Resumable)."""
        world = np.array([self.world(run.world)], dtype=np.int64)
        with self._ordered():
            started, tick = self.trajectories.resume(run, source)
            target = np.array([run.target])
            kind = "trajectory_resume"
            self._announce(Accepted(source, kind, world, target, tick, None, run.as_json()))
        return started

    def _stage_one(
        self,
        kind: str,
        source: Source,
        stage: Callable[[int, Mapping[int, float]], CommandResult],
        world: int,
        values: Mapping[int, float],
    ) -> CommandResult:
        """Stage one world's command in order with every other, and tell the listeners which
        joints it named (a trajectory stops only if it drives one of them)."""
        with self._ordered():
            result = stage(world, values)
            if self._listeners:
                worlds = np.array([result.world], dtype=np.int64)
                row, joints = result.target[None, :], tuple(values)
                self._announce(Accepted(source, kind, worlds, row, result.tick, joints=joints))
        return result

    # -- the JSON op protocol of the WebSocket surfaces ------------------------------------

    def handle(self, msg: Any, default_world: int | None, source: Source) -> dict[str, Any]:
        """One decoded client message → an ack or error frame (dict); never raises.

        `{"op": "increment" | "set_targets" | "reset", "id": ..., "world": ..., ...}`; on a
        socket bound to one world, `world` may be left out and must match when given.
        """
        msg_id = msg.get("id") if isinstance(msg, dict) else None
        try:
            if not isinstance(msg, dict):
                raise BadCommand("message", "a message must be a JSON object with an `op`")
            body = {k: v for k, v in msg.items() if k not in ("id", "op", "world")}
            op = msg.get("op")
            world = msg.get("world", default_world)
            if default_world is not None and world != default_world:
                raise BadCommand("world", f"this socket controls world {default_world} only")
            if world is None:
                raise BadCommand("world", "`world` (an integer id) is required on this socket")
            world = self.world(world)
            if op == "increment":
                req = IncrementRequest.model_validate(body)
                field_name = "deltas" if req.deltas is not None else "joint"
                result = self.increment(world, req.as_mapping(), source, field_name)
            elif op == "set_targets":
                req_t = JointTargets.model_validate(body)
                result = self.command_targets(world, req_t.name, req_t.position, source)
            elif op in trajectory_ops.OPS:
                return trajectory_ops.handle(self, op, msg_id, world, body, source)
            elif op == "reset":
                if body:
                    extra = next(iter(body))
                    raise BadCommand(extra, "reset takes no fields besides op, id and world")
                done = self.reset([world], source)
                result = CommandResult(world, done.targets[0], [], done.tick)
            else:
                raise BadCommand("op", f"unknown op {op!r}; ops are {sorted(_OPS)}")
            return wire.ack(msg_id, result)
        except ArmfleetError as exc:
            return wire.error_frame(msg_id, exc)
        except ValidationError as exc:
            return wire.error_frame(msg_id, validation_detail(exc))


_OPS = ("increment", "reset", "set_targets", *trajectory_ops.OPS)


def validation_detail(exc: ValidationError) -> str:
    """pydantic's errors as one line: `loc: msg; loc: msg`."""
    return "; ".join(
        f"{'.'.join(str(p) for p in err['loc']) or 'message'}: {err['msg']}" for err in exc.errors()
    )
