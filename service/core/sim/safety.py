"""Each world's safety mode: NORMAL, or PROTECTIVE_STOP until it is unlocked.

Why in the core: a protective stop is a state of the world, not of one connection. Every
surface reports it (the world's state and TCP over REST, the WebSocket, RTDE's safety_mode and
status bits, the Dashboard's safetystatus, `GET /v1/ur`), and every surface's commands that
would move the arm are refused while it holds (`Control.run`, 409), so a REST client cannot
drive an arm that a UR program just had stopped. What raises a stop is the robot's safety
system, on every world: the core's clearance watch (core/commands/clearance_watch.py: a
commanded target into a fixed obstacle) and torque watch (core/commands/torque_watch.py: a
joint held at its torque limit), a user's trigger (`trigger_protective_stop` over REST and the
WebSocket, ur_rtde's triggerProtectiveStop on a world with UR ports), each through the
`protective_stop` command (core/commands/safety_stop.py: the arm held in the same step). What
clears it is an unlock 5 s after the stop at the earliest (the Dashboard's `unlock protective
stop`, or `unlock_protective_stop` over REST and the WebSocket; the robot's rule: "Cannot
unlock protective stop until 5s after occurrence"), or a reset of the world (a new episode:
the world is back at home).

The modes are UR's numbers (RTDE safety_mode: 1 NORMAL, 3 PROTECTIVE_STOP) and names. The
5 s are counted on the wall clock, as the robot's are: an operator's rule, not physics.
Thread-safe: the UR event loop, command callers and the sim thread all read it. Who must act
on a stop besides the core's refusal (the UR surface ends the world's control script) listens
with `on_stop`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from service.core.errors import ProtectiveStopped
from service.core.sim.batch import Batch
from service.core.sim.loop_types import SnapshotSink
from service.core.sim.types import Snapshot

log = logging.getLogger("armfleet.safety")

__all__ = ["NORMAL", "PROTECTIVE_STOP", "UNLOCK_AFTER_S", "SafetyTable"]

NORMAL, PROTECTIVE_STOP = 1, 3
NAMES = {NORMAL: "NORMAL", PROTECTIVE_STOP: "PROTECTIVE_STOP"}
UNLOCK_AFTER_S = 5.0  # a protective stop may be unlocked this long after it happened


class SafetyTable(SnapshotSink):
    """The safety mode of `nworld` worlds (see the module docstring). The loop's first sink:
    every snapshot it publishes carries the modes as of then (`Snapshot.safety`)."""

    def __init__(self, nworld: int) -> None:
        self._mode = np.full(nworld, NORMAL, dtype=np.int8)
        self._at = np.zeros(nworld)  # time.monotonic() of each world's last stop
        self._why: dict[int, str] = {}
        self.versions = np.zeros(nworld, dtype=np.int64)  # bumped at every change of a world
        self._lock = threading.Lock()
        self._on_stop: tuple[Callable[[int, str], None], ...] = ()

    def on_stop(self, listener: Callable[[int, str], None]) -> None:
        """Call `listener(world, why)` after every stop, on the stopping thread (quick: hand
        real work to a thread or event loop of one's own)."""
        self._on_stop = (*self._on_stop, listener)

    def modes(self) -> np.ndarray:
        """Every world's mode (nworld,) int8, a copy (a snapshot's `safety`)."""
        return self._mode.copy()

    def extend_snapshot(self, snap: Snapshot, batch: Batch) -> Snapshot:
        return replace(snap, safety=self.modes())

    def mode(self, world: int) -> int:
        return int(self._mode[world])

    def why(self, world: int) -> str | None:
        """What stopped `world` (None while NORMAL)."""
        with self._lock:
            return self._why.get(world)

    def stop(self, world: int, why: str) -> bool:
        """Protective-stop `world`; False if it already was (the first cause is kept). Only
        the safety commands call it (core/commands/safety_stop.py: the arm is held first)."""
        with self._lock:
            if self._mode[world] == PROTECTIVE_STOP:
                return False
            self._mode[world] = PROTECTIVE_STOP
            self._at[world] = time.monotonic()
            self._why[world] = why
            self.versions[world] += 1
        for listener in self._on_stop:
            try:
                listener(world, why)
            except Exception:  # a listener must never cost the stop itself
                log.exception("protective stop listener %r failed", listener)
        return True

    def age(self, world: int) -> float:
        """Seconds since `world`'s last stop (wall clock, as the unlock rule counts)."""
        return time.monotonic() - float(self._at[world])

    def unlock(self, world: int) -> bool:
        """Back to NORMAL; False (nothing changed) while the stop is younger than
        UNLOCK_AFTER_S. True for a world that is not stopped."""
        with self._lock:
            if self._mode[world] != PROTECTIVE_STOP:
                return True
            if time.monotonic() - self._at[world] < UNLOCK_AFTER_S:
                return False
            self._clear(world)
            return True

    def clear(self, worlds: list[int] | np.ndarray) -> None:
        """Back to NORMAL at once, whatever the age of the stop (a reset, a restarted safety
        system, a controller handed to a new lease)."""
        with self._lock:
            for w in np.asarray(worlds, dtype=np.int64).tolist():
                if self._mode[w] != NORMAL:
                    self._clear(w)

    def _clear(self, world: int) -> None:
        self._mode[world] = NORMAL
        self._why.pop(world, None)
        self.versions[world] += 1

    def refuse_if_stopped(self, worlds: list[int] | np.ndarray | None) -> None:
        """ProtectiveStopped (409) naming the first of `worlds` (None: all) that is stopped."""
        if not (self._mode != NORMAL).any():  # the common case: nothing stopped anywhere
            return
        ids = np.arange(len(self._mode)) if worlds is None else np.asarray(worlds, np.int64)
        stopped = ids[self._mode[ids] == PROTECTIVE_STOP]
        if stopped.size:
            w = int(stopped[0])
            why = self.why(w) or "protective stop"
            raise ProtectiveStopped(
                f"world {w} is protective-stopped ({why}): unlock it with the Dashboard's "
                f"`unlock protective stop` ({UNLOCK_AFTER_S:g} s after the stop at the "
                "earliest) or reset the world",
                "world",
            )


def names(modes: np.ndarray) -> list[str]:
    """The names of modes (k,): what the JSON state frames carry (at once when all are NORMAL,
    as nearly always: a frame of 65,536 worlds would otherwise spend ms naming them)."""
    if (modes == NORMAL).all():
        return ["NORMAL"] * len(modes)
    return [NAMES.get(int(m), "NORMAL") for m in modes]
