"""What the service returns, as typed results built from its JSON.

Each class follows one reply schema of the server (service/core/contract/replies.py);
`from_json` reads the fields it knows and ignores the rest, so a newer server that adds a field
does not break an older client. Nothing about the robot is written here: joint names, limits and
home come from `/v1/info` (`Info.joints`, each a `JointSpec`, the class the service itself
describes joints with) and every state carries its joint names (`name`).

Arrays are numpy float64; JSON null (a NaN on the server side) becomes NaN.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from clients.entity_states import EntityStates

JointRef = str | int  # a joint by name ("elbow_joint") or by index in `Info.joints` (2)
WorldSpec = int | str | Iterable[int] | None  # one world, "0-63", [0, 3, 7], or None: all


def _arr(values: Any) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64)


def _arr2(rows: Any, width: int) -> np.ndarray:
    out = np.array([[np.nan if v is None else v for v in row] for row in rows], dtype=np.float64)
    return out.reshape(len(rows), width)


def joint_index(names: Sequence[str], joint: JointRef) -> int:
    """The index of `joint` (a name or an index) among `names`; KeyError/IndexError naming the
    joints there are."""
    if isinstance(joint, int) and not isinstance(joint, bool):
        if 0 <= joint < len(names):
            return joint
        raise IndexError(f"joint index {joint} out of range 0..{len(names) - 1}")
    try:
        return list(names).index(joint)
    except ValueError:
        raise KeyError(f"unknown joint {joint!r}; joints are {list(names)}") from None


@dataclass(frozen=True)
class JointSpec:
    """One commanded joint as the outside world sees it: `/v1/info` lists these. The service
    builds its robot description from this very class (service.core.sim.types imports it from
    here), so the two cannot drift apart, and the client needs nothing of the service.

    name: joint name, as in sensor_msgs/JointState and the MJCF
    lower, upper: joint range [rad]; targets are clamped to it
    home: value in the `home` keyframe [rad]
    velocity_limit: rated maximum speed [rad/s] (informative; MuJoCo does not enforce it)
    effort_limit: actuator force limit [N·m]
    """

    name: str
    lower: float
    upper: float
    home: float
    velocity_limit: float
    effort_limit: float


JointInfo = JointSpec  # the client's name for it


@dataclass(frozen=True)
class Info:
    """GET /v1/info: the robot, its joints, the batch and how fast time goes."""

    robot: str
    joints: tuple[JointInfo, ...]
    nworld: int
    device: str
    shards: int  # processes the worlds are split across
    control_hz: float
    physics_dt: float  # [s] one physics step
    substeps: int  # physics steps per control tick
    mode: str  # realtime | fast | paused
    tick: int
    sim_time: float  # tick / control_hz [s]
    ticks_per_s: float  # measured over the last second
    realtime_factor: float  # simulated seconds per wall second
    captured: bool  # the control tick replays a captured graph

    @property
    def names(self) -> list[str]:
        """The joint names, in the order every state and target array uses."""
        return [j.name for j in self.joints]

    @property
    def home(self) -> np.ndarray:
        """The 7 targets a reset restores [rad]."""
        return np.array([j.home for j in self.joints], dtype=np.float64)

    def joint(self, joint: JointRef) -> JointInfo:
        """One joint's facts, by name or index."""
        return self.joints[joint_index(self.names, joint)]

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Info:
        fields = {k: d[k] for k in cls.__dataclass_fields__ if k != "joints"}
        known = JointInfo.__dataclass_fields__
        joints = tuple(JointInfo(**{k: j[k] for k in known}) for j in d["joints"])
        return cls(joints=joints, **fields)


@dataclass(frozen=True, eq=False)
class WorldState:
    """One world at one tick: JointState fields (arrays of 7), target, flange pose, faults."""

    world: int
    tick: int
    sim_time: float  # simulated seconds since this world's last reset
    name: tuple[str, ...]  # joint names, the order of every array below
    position: np.ndarray  # (7,) [rad]
    velocity: np.ndarray  # (7,) [rad/s]
    effort: np.ndarray  # (7,) actuator force/torque
    target: np.ndarray  # (7,) commanded [rad]
    flange_position: np.ndarray  # (3,) x y z [m], world frame
    flange_quaternion: np.ndarray  # (4,) w x y z
    faults: int  # times this world was reset for NaN or capacity overflow
    # "NORMAL", or "PROTECTIVE_STOP" until the Dashboard unlocks it (or the world is reset)
    safety_mode: str = "NORMAL"
    # Only while the service is paused: targets as of every accepted command (a paused service
    # applies them at once, so they equal `target` once applied).
    pending_target: np.ndarray | None = None
    entities: EntityStates | None = None  # only when asked for (entities=True)

    def index(self, joint: JointRef) -> int:
        return joint_index(self.name, joint)

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> WorldState:
        return cls(
            world=int(d["world"]),
            tick=int(d["tick"]),
            sim_time=float(d["sim_time"]),
            name=tuple(d["name"]),
            position=_arr(d["position"]),
            velocity=_arr(d["velocity"]),
            effort=_arr(d["effort"]),
            target=_arr(d["target"]),
            flange_position=_arr(d["flange"]["position"]),
            flange_quaternion=_arr(d["flange"]["quaternion"]),
            faults=int(d["faults"]),
            safety_mode=str(d.get("safety_mode", "NORMAL")),
            pending_target=_arr(d["pending_target"]) if "pending_target" in d else None,
            entities=EntityStates.from_list(d["entities"]) if "entities" in d else None,
        )


# BatchStates' per-joint columns and the other float columns with their widths.
_JOINT_COLUMNS = ("position", "velocity", "effort", "target")
_FLANGE_COLUMNS = (("flange_position", 3), ("flange_quaternion", 4))
_ROW_ARRAYS = (*_JOINT_COLUMNS, *(name for name, _ in _FLANGE_COLUMNS))


@dataclass(frozen=True, eq=False)
class BatchStates:
    """Several worlds at one tick; row i of every array belongs to `worlds[i]`."""

    tick: int
    name: tuple[str, ...]
    worlds: np.ndarray  # (n,) int
    sim_time: np.ndarray  # (n,)
    position: np.ndarray  # (n, 7)
    velocity: np.ndarray  # (n, 7)
    effort: np.ndarray  # (n, 7)
    target: np.ndarray  # (n, 7)
    flange_position: np.ndarray  # (n, 3)
    flange_quaternion: np.ndarray  # (n, 4) w x y z
    faults: np.ndarray  # (n,) int
    pending_target: np.ndarray | None = None  # (n, 7), only while the service is paused
    safety_mode: tuple[str, ...] | None = None  # (n,) names; None: not in the frame (a
    # binary frame of a server before its layout 2: clients/wire.py)
    entities: EntityStates | None = None  # (n, ne, ...) arrays, only when asked for

    def __len__(self) -> int:
        return int(self.worlds.shape[0])

    def row(self, world: int) -> int:
        hits = np.flatnonzero(self.worlds == world)
        if hits.size == 0:
            raise KeyError(f"world {world} is not in this batch ({self.worlds.tolist()})")
        return int(hits[0])

    def world(self, world: int) -> WorldState:
        """One world of the batch as a WorldState."""
        i = self.row(world)
        rows = {k: getattr(self, k)[i] for k in _ROW_ARRAYS}
        return WorldState(
            world=int(world),
            tick=self.tick,
            sim_time=float(self.sim_time[i]),
            name=self.name,
            faults=int(self.faults[i]),
            safety_mode="NORMAL" if self.safety_mode is None else self.safety_mode[i],
            pending_target=None if self.pending_target is None else self.pending_target[i],
            entities=None if self.entities is None else self.entities.row(i),
            **rows,
        )

    def __iter__(self) -> Iterator[WorldState]:
        return (self.world(int(w)) for w in self.worlds)

    @classmethod
    def from_rows(cls, d: Mapping[str, Any]) -> BatchStates:
        """GET /v1/worlds/state: `{"tick", "worlds": [<world state>, ...]}`."""
        rows = d["worlds"]
        columns: dict[str, Any] = {
            "tick": d["tick"],
            "name": rows[0]["name"] if rows else [],
            "worlds": [r["world"] for r in rows],
            "sim_time": [r["sim_time"] for r in rows],
            "faults": [r["faults"] for r in rows],
            "safety_mode": [r.get("safety_mode", "NORMAL") for r in rows],
            "flange_position": [r["flange"]["position"] for r in rows],
            "flange_quaternion": [r["flange"]["quaternion"] for r in rows],
        }
        columns.update({k: [r[k] for r in rows] for k in _JOINT_COLUMNS})
        if rows and "pending_target" in rows[0]:
            columns["pending_target"] = [r["pending_target"] for r in rows]
        batch = cls.from_columns(columns)
        if rows and "entities" in rows[0]:
            each = [EntityStates.from_list(r["entities"]) for r in rows]
            batch = dataclasses.replace(batch, entities=EntityStates.stack(each))
        return batch

    @classmethod
    def from_columns(cls, d: Mapping[str, Any]) -> BatchStates:
        """A `{"op": "states"}` WebSocket frame (column-wise)."""
        names = tuple(d["name"])
        n = len(d["worlds"])
        floats = {k: _arr2(d[k], len(names)) for k in _JOINT_COLUMNS}
        floats.update({k: _arr2(d[k], width) for k, width in _FLANGE_COLUMNS})
        pending = d.get("pending_target")
        entities = d.get("entities")
        safety = d.get("safety_mode")
        return cls(
            tick=int(d["tick"]),
            name=names,
            worlds=np.array(d["worlds"], dtype=np.int64).reshape(n),
            sim_time=_arr(d["sim_time"]),
            faults=np.array(d["faults"], dtype=np.int64).reshape(n),
            pending_target=None if pending is None else _arr2(pending, len(names)),
            safety_mode=None if safety is None else tuple(safety),
            entities=None if entities is None else EntityStates.from_columns(entities, n),
            **floats,
        )


@dataclass(frozen=True, eq=False)
class CommandAck:
    """Reply to a target command (HTTP or WebSocket): the world's 7 targets after it (clamped
    as the server clamps), the joints that hit a limit, and the first tick stepped with it."""

    world: int
    target: np.ndarray  # (7,) [rad]
    clamped: tuple[str, ...]
    tick: int
    id: Any = None  # the WebSocket message id it answers (None over HTTP)

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CommandAck:
        return cls(
            world=int(d["world"]),
            target=_arr(d["target"]),
            clamped=tuple(d.get("clamped", ())),
            tick=int(d["tick"]),
            id=d.get("id"),
        )


@dataclass(frozen=True, eq=False)
class BatchAck:
    """Reply to `set_many`: all results take effect at `tick`."""

    tick: int
    results: tuple[CommandAck, ...]

    @property
    def worlds(self) -> np.ndarray:
        return np.array([r.world for r in self.results], dtype=np.int64)

    @property
    def target(self) -> np.ndarray:
        return np.stack([r.target for r in self.results]) if self.results else np.zeros((0, 7))

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BatchAck:
        return cls(
            tick=int(d["tick"]), results=tuple(CommandAck.from_json(r) for r in d["results"])
        )


@dataclass(frozen=True)
class ResetResult:
    """Reply to a reset: the worlds put back to home, from `tick` on."""

    worlds: tuple[int, ...]  # the worlds put back to home
    tick: int  # the first tick stepped from home

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ResetResult:
        worlds = tuple(int(w) for w in d["worlds"])
        return cls(worlds=worlds, tick=int(d["tick"]))


@dataclass(frozen=True)
class SafetyAck:
    """Reply to `trigger_protective_stop` / `unlock_protective_stop`: the world's safety mode
    after it, from `tick` on, and (a stop) its cause: the first stop's, which a second keeps."""

    world: int
    tick: int
    safety_mode: str  # "PROTECTIVE_STOP" after a trigger, "NORMAL" after an unlock
    why: str | None = None  # a trigger's: the stop's cause; None after an unlock

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SafetyAck:
        why = d.get("why")
        return cls(int(d["world"]), int(d["tick"]), str(d["safety_mode"]), why)


@dataclass(frozen=True)
class Lease:
    """Worlds lent to this client (`ArmfleetClient.lease`): only they answer to `token`."""

    id: str
    worlds: tuple[int, ...]
    label: str
    ttl_s: float  # [s] from the last grant or renewal
    expires_at: float  # wall clock, seconds since the epoch
    token: str | None = field(default=None, repr=False)  # never printed

    @property
    def world(self) -> int:
        """The first (with `count=1`, the only) world of the lease."""
        return self.worlds[0]

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Lease:
        worlds = tuple(int(w) for w in d["worlds"])
        return cls(
            str(d["id"]),
            worlds,
            str(d["label"]),
            float(d["ttl_s"]),
            float(d["expires_at"]),
            d.get("token"),
        )


@dataclass(frozen=True)
class SimStatus:
    """Reply of pause / resume / set_mode / step: the mode now and the tick reached."""

    mode: str  # realtime | fast | paused
    tick: int  # the tick reached (after `step`: the last of the n)

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SimStatus:
        return cls(mode=str(d["mode"]), tick=int(d["tick"]))


@dataclass(frozen=True)
class ConnectionStatus:
    """Reported by `stream(..., on_status=...)` whenever the stream connects or drops.

    connected: a socket is open and frames flow
    detail: why it dropped (or the URL it connected to)
    attempt: consecutive failed attempts so far (0 when connected)
    retry_in: seconds until the next attempt (None when connected or giving up)
    """

    connected: bool
    detail: str
    attempt: int = 0
    retry_in: float | None = None


@dataclass(frozen=True)
class WsError:
    """`{"op": "error", "id", "detail"}` from the server: the command `id` was refused."""

    id: Any
    detail: str
