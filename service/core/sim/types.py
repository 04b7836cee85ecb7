"""Data structures shared by the engine, the loop and the API (the engine protocol: batch.py).

They are plain frozen dataclasses over numpy arrays so that the engine (which knows MuJoCo Warp)
and the API (which knows JSON) meet on something neither owns; a snapshot's poses (`Poses`) may
be computed when first read.
"""

from __future__ import annotations

import enum
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

# Defined with the client's models (the wire's own description of a joint), so that the client
# installs without the service and the two cannot drift apart.
from clients.models import JointSpec
from service.core.sim.randomizations import Randomized


def _frozen(values: list[float]) -> np.ndarray:
    out = np.array(values, dtype=np.float64)
    out.flags.writeable = False
    return out


# The commanded joints: six arm joints, then finger_joint. Every per-world table of targets and
# joint states is (nworld, NJOINT); the model names them (robot.py checks it has this many).
NJOINT = 7


@dataclass(frozen=True)
class RobotSpec:
    """The commanded joints of the robot, in command order (six arm joints, then finger_joint)."""

    name: str
    joints: tuple[JointSpec, ...]

    # Derived once: every command clamps against these. Read-only so that sharing is safe.
    @cached_property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @cached_property
    def lower(self) -> np.ndarray:
        return _frozen([j.lower for j in self.joints])

    @cached_property
    def upper(self) -> np.ndarray:
        return _frozen([j.upper for j in self.joints])

    @cached_property
    def home(self) -> np.ndarray:
        return _frozen([j.home for j in self.joints])

    def index(self, joint: str | int) -> int:
        """Joint index from a name or an index; raises KeyError naming the valid choices."""
        if isinstance(joint, int) and not isinstance(joint, bool):
            if 0 <= joint < len(self.joints):
                return joint
            raise KeyError(f"joint index {joint} out of range 0..{len(self.joints) - 1}")
        for i, j in enumerate(self.joints):
            if j.name == joint:
                return i
        raise KeyError(f"unknown joint {joint!r}; joints are {self.names}")


class Poses:
    """Positions and quaternions in a Snapshot (the flange's, every body's): given, or
    computed once, by the first reader, under a lock.

    The native engine's tick does not leave them at hand (MuJoCo's derived fields describe
    the state before the last substep), computing them costs a few percent of a tick on the
    cores that step the physics, and most snapshots are never asked for them: it hands
    `compute` instead. Pickles as arrays (snapshots cross process boundaries between shards).
    """

    __slots__ = ("_compute", "_lock", "_pos", "_quat")

    def __init__(
        self,
        pos: np.ndarray | None = None,
        quat: np.ndarray | None = None,
        compute: Callable[[], tuple[np.ndarray, np.ndarray]] | None = None,
    ) -> None:
        if (pos is None or quat is None) == (compute is None):
            raise ValueError("Poses takes either pos and quat or compute")
        self._pos, self._quat, self._compute = pos, quat, compute
        self._lock = threading.Lock()

    def get(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions (..., 3), quaternions (..., 4) w x y z)."""
        if self._pos is None:
            with self._lock:
                if self._pos is None:
                    assert self._compute is not None
                    self._pos, self._quat = self._compute()
                    self._compute = None
        assert self._quat is not None
        return self._pos, self._quat

    def __reduce__(self) -> tuple[type[Poses], tuple[np.ndarray, np.ndarray]]:
        return (Poses, self.get())


@dataclass(frozen=True)
class EntityFrame:
    """The scene's entities (named free bodies) in some worlds at one tick, as the engine holds
    them (float32 on MuJoCo Warp, float64 on native MuJoCo): what a state frame carries when a
    client asks for entities.

    names: entity names, the order of axis 1 below                              (ne,)
    worlds: the world id of each row, ascending                                 (k,)
    position: x y z [m], world frame                                            (k, ne, 3)
    orientation: quaternion w x y z                                             (k, ne, 4)
    linear: linear velocity [m/s], world frame                                  (k, ne, 3)
    angular: angular velocity [rad/s], the body's own frame (MuJoCo's free joint) (k, ne, 3)
    """

    names: tuple[str, ...]
    worlds: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    linear: np.ndarray
    angular: np.ndarray

    def take(self, ids: np.ndarray) -> EntityFrame:
        """The rows of worlds `ids` (each one of `worlds`), in the order of `ids`."""
        rows = np.searchsorted(self.worlds, ids)
        return EntityFrame(
            self.names,
            np.asarray(ids),
            *(np.ascontiguousarray(a[rows]) for a in self.arrays()),
        )

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.position, self.orientation, self.linear, self.angular


@dataclass(frozen=True)
class Snapshot:
    """One consistent view of every world at the end of one control tick.

    tick: control ticks completed by the batch since start
    sim_time: per-world simulated seconds since that world's last reset        (nworld,)
    position, velocity: the commanded joints' qpos [rad] and qvel [rad/s]        (nworld, 7)
    effort: actuator torque on each commanded joint [N·m], gravity comp included (nworld, 7)
    target: position targets in effect during this tick [rad]                  (nworld, 7)
    flange: the flange site's pose (`Poses`), read as flange_pos and flange_quat:
      flange_pos: position in the world frame [m]                              (nworld, 3)
      flange_quat: orientation, quaternion w x y z                            (nworld, 4)
    faults: how often each world has been reset for NaN or capacity overflow   (nworld,)
    bodies: every body's pose (`Poses`), read as body_pos and body_quat:
      body_pos: every body's origin in the world frame [m], float32             (nworld, nbody, 3)
      body_quat: every body's orientation, quaternion w x y z, float32         (nworld, nbody, 4)
        (bodies in MjModel order, 0 = world; what viewers draw, see GET /v1/scene)
    entities: every world's entities (`EntityFrame`), only in snapshots taken while a client
      asks for entities in its frames (None otherwise: no cost for those that do not)
    safety: every world's safety mode (UR's numbers: 1 NORMAL, 3 PROTECTIVE_STOP; safety.py)
      at the snapshot, stamped by the loop; None (all NORMAL) in an engine's own snapshot (nworld,)
    """

    tick: int
    sim_time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    target: np.ndarray
    faults: np.ndarray
    flange: Poses
    bodies: Poses
    entities: EntityFrame | None = None
    safety: np.ndarray | None = None

    # positions (.., 3) and quaternions (.., 4, w x y z), computed when first read
    flange_pos = property(lambda self: self.flange.get()[0])
    flange_quat = property(lambda self: self.flange.get()[1])
    body_pos = property(lambda self: self.bodies.get()[0])
    body_quat = property(lambda self: self.bodies.get()[1])

    @property
    def nworld(self) -> int:
        return int(self.position.shape[0])


class Mode(enum.StrEnum):
    """How the loop advances time."""

    REALTIME = "realtime"  # paced to the wall clock; catches up at most 0.1 s, else RTF < 1
    FAST = "fast"  # as fast as the machine allows
    PAUSED = "paused"  # only on an explicit step request


# MuJoCo's integration state (mjSTATE_INTEGRATION minus plugins, which neither engine uses), as
# named mjData fields. Everything else in mjData is recomputed from these within a step, so these
# plus the batch's own counters are what a restored batch needs to continue bit-identically.
PHYSICS_FIELDS = (
    "time",
    "qpos",
    "qvel",
    "act",
    "history",
    "plastic",
    "qacc_warmstart",
    "ctrl",
    "qfrc_applied",
    "xfrc_applied",
    "eq_active",
    "mocap_pos",
    "mocap_quat",
    "userdata",
    # Not integration state: the actuator forces of the last step, restored so that the snapshot
    # at the restored tick reports the same effort as the one taken when the state was saved.
    "qfrc_actuator",
)


# Keys of `BatchState.physics` that hold per-world model fields rather than mjData state.
MODEL_PREFIX = "model."


@dataclass(frozen=True)
class BatchState:
    """Everything a batch needs to continue exactly where it was, at a tick boundary.

    `Batch.get_state()` returns one, `Batch.set_state()` takes one of the same model and number
    of worlds: after set_state, stepping with the same commands gives bit-identical states to
    stepping the batch the state was taken from (same engine and device). Arrays are host copies.

    tick: control ticks completed by the batch when the state was taken
    world_ticks: ticks since each world's last reset (sim_time = world_ticks × tick_dt) (nworld,)
    faults: how often each world has been reset for NaN or capacity overflow           (nworld,)
    targets: the commanded position targets [rad], float64 host mirror                 (nworld, 7)
    physics: MuJoCo integration state, keyed by mjData field name (`PHYSICS_FIELDS`), each
        (nworld, ...) in the engine's own dtype (float32 on MuJoCo Warp) so that nothing is
        rounded: time [s] (nworld,), qpos (nworld, nq), qvel (nworld, nv), act (nworld, na),
        history, plastic, qacc_warmstart (the solver's warm start, nworld × nv), ctrl
        (nworld, nu), qfrc_applied (nworld, nv), xfrc_applied (nworld, nbody, 6), eq_active
        (nworld, neq) bool, mocap_pos (nworld, nmocap, 3), mocap_quat (nworld, nmocap, 4),
        userdata (nworld, nuserdata); and qfrc_actuator (nworld, nv) [N·m], the last step's
        actuator forces, so that the restored tick's snapshot shows the same effort;
        besides, "model.<field>" (nworld, ...) float64 for every MjModel field a command gave
        per-world values (`MODEL_PREFIX`; a field absent here has the scene's values)
    """

    tick: int
    world_ticks: np.ndarray
    faults: np.ndarray
    targets: np.ndarray
    physics: dict[str, np.ndarray]
    # per world, the last randomisation this state holds (`randomizations.py`; filled by the
    # loop, not the engines, which neither need nor keep it); worlds without one are absent
    randomized: dict[int, Randomized] = field(default_factory=dict)

    @property
    def nworld(self) -> int:
        return int(self.targets.shape[0])

    def check_compatible(self, nworld: int, shapes: dict[str, tuple[int, ...]]) -> None:
        """Raise ValueError naming the mismatch unless this state fits a batch of that shape.

        `shapes` maps each physics field to its per-world shape in the receiving batch.
        """
        if self.nworld != nworld:
            raise ValueError(f"state has {self.nworld} worlds, the batch has {nworld}")
        rows = {"world_ticks": self.world_ticks, "faults": self.faults, "targets": self.targets}
        for name, arr in rows.items():
            if arr.shape[0] != nworld:
                raise ValueError(f"{name} has {arr.shape[0]} rows, expected {nworld}")
        if self.targets.ndim != 2 or self.targets.shape[1] != 7:
            raise ValueError(f"targets has shape {self.targets.shape}, expected ({nworld}, 7)")
        for name, shape in shapes.items():
            arr = self.physics.get(name)
            if arr is None:
                raise ValueError(f"physics field {name!r} missing")
            if arr.shape != (nworld, *shape):
                raise ValueError(
                    f"physics field {name!r} has shape {arr.shape}, expected {(nworld, *shape)}"
                )
            if arr.dtype != bool and not np.isfinite(arr).all():
                raise ValueError(f"physics field {name!r} holds non-finite values")
