"""Trajectories from the client side: bodies, calls, replies, and waiting for the outcome.

Like `clients.calls`, nothing here does I/O: `ArmfleetClient` and `AsyncArmfleetClient` run
these `Call`s, so the two twins share every path, body and parse. A trajectory is given as
trajectory_msgs/JointTrajectory fields:

    arm.follow_trajectory(0, ["shoulder_pan_joint", "elbow_joint"],
                          [point([0.5, 1.2], 1.0), point([0.0, 1.57], 2.0)])
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from clients.calls import Call, worlds_param
from clients.models import WorldSpec

MAX_WAIT_S = 30.0  # one long poll of GET .../trajectory?wait= (the server allows up to 60 s)


def point(
    positions: Sequence[float],
    time_from_start: float,
    velocities: Sequence[float] = (),
    accelerations: Sequence[float] = (),
) -> dict[str, Any]:
    """One trajectory_msgs/JointTrajectoryPoint as the service reads it (seconds as a float)."""
    return {
        "positions": [float(v) for v in positions],
        "velocities": [float(v) for v in velocities],
        "accelerations": [float(v) for v in accelerations],
        "time_from_start": float(time_from_start),
    }


def tolerance(name: str, position: float = 0.0, velocity: float = 0.0) -> dict[str, Any]:
    """control_msgs/JointTolerance: > 0 is checked, 0 is not."""
    return {"name": name, "position": float(position), "velocity": float(velocity)}


def trajectory_body(
    joint_names: Sequence[str],
    points: Iterable[Mapping[str, Any]],
    path_tolerance: Iterable[Mapping[str, Any]] = (),
    goal_tolerance: Iterable[Mapping[str, Any]] = (),
    goal_time_tolerance: float = 0.0,
) -> dict[str, Any]:
    """The JSON body of POST /v1/worlds/{w}/trajectory (and `trajectory` of the batch call)."""
    return {
        "joint_names": list(joint_names),
        "points": [dict(p) for p in points],
        "path_tolerance": [dict(t) for t in path_tolerance],
        "goal_tolerance": [dict(t) for t in goal_tolerance],
        "goal_time_tolerance": float(goal_time_tolerance),
    }


@dataclass(frozen=True)
class TrajectoryStarted:
    """A trajectory accepted for one world: its id, first tick, and the tick of its end."""

    id: int
    world: int
    start_tick: int
    end_tick: int

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TrajectoryStarted:
        return cls(int(d["id"]), int(d["world"]), int(d["start_tick"]), int(d["end_tick"]))


@dataclass(frozen=True, eq=False)
class TrajectoriesStarted:
    """One trajectory started on many worlds at `start_tick`; ids[i] runs on worlds[i]."""

    start_tick: int
    end_tick: int
    ids: np.ndarray
    worlds: np.ndarray

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TrajectoriesStarted:
        return cls(
            int(d["start_tick"]),
            int(d["end_tick"]),
            np.asarray(d["ids"], dtype=np.int64),
            np.asarray(d["worlds"], dtype=np.int64),
        )


@dataclass(frozen=True, eq=False)
class TrajectoryStatus:
    """A trajectory's state (running, succeeded, aborted), why it was aborted, its progress
    (0..1 at `tick`) and feedback (desired, actual, error per joint of `joint_names`)."""

    id: int
    world: int
    state: str
    reason: str | None
    detail: str
    joint_names: tuple[str, ...]
    start_tick: int
    end_tick: int
    tick: int
    progress: float
    desired: np.ndarray
    actual: np.ndarray
    error: np.ndarray
    finished_tick: int | None

    @property
    def done(self) -> bool:
        return self.state != "running"

    @property
    def succeeded(self) -> bool:
        return self.state == "succeeded"

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TrajectoryStatus:
        def arr(key: str) -> np.ndarray:
            return np.array([np.nan if v is None else v for v in d.get(key, ())], dtype=float)

        return cls(
            id=int(d["id"]),
            world=int(d["world"]),
            state=str(d["state"]),
            reason=d.get("reason"),
            detail=str(d.get("detail", "")),
            joint_names=tuple(d.get("joint_names", ())),
            start_tick=int(d["start_tick"]),
            end_tick=int(d["end_tick"]),
            tick=int(d["tick"]),
            progress=float(d["progress"]),
            desired=arr("desired"),
            actual=arr("actual"),
            error=arr("error"),
            finished_tick=None if d.get("finished_tick") is None else int(d["finished_tick"]),
        )


# -- the calls ----------------------------------------------------------------------------------


def start_call(world: int, body: Mapping[str, Any]) -> Call:
    path = f"/v1/worlds/{int(world)}/trajectory"
    return Call("POST", path, TrajectoryStarted.from_json, json=dict(body))


def start_many_call(worlds: WorldSpec, body: Mapping[str, Any]) -> Call:
    spec = worlds_param(worlds)
    if spec is None:
        raise ValueError("name the worlds: ids, or ranges like '0-9999'")
    payload = {"worlds": spec, "trajectory": dict(body)}
    return Call("POST", "/v1/trajectories", TrajectoriesStarted.from_json, json=payload)


def status_call(world: int, wait: float = 0.0) -> Call:
    """The world's running (else last) trajectory; `wait` long-polls for its outcome."""
    params = {"wait": repr(float(wait))} if wait > 0 else None
    path = f"/v1/worlds/{int(world)}/trajectory"
    return Call("GET", path, TrajectoryStatus.from_json, params=params, read_timeout=wait + 10)


def by_id_call(traj_id: int, wait: float = 0.0) -> Call:
    """One trajectory by id, whatever ran on its world since; `wait` as in `status_call`."""
    params = {"wait": repr(float(wait))} if wait > 0 else None
    path = f"/v1/trajectories/{int(traj_id)}"
    return Call("GET", path, TrajectoryStatus.from_json, params=params, read_timeout=wait + 10)


def cancel_call(world: int) -> Call:
    return Call("DELETE", f"/v1/worlds/{int(world)}/trajectory", TrajectoryStatus.from_json)


class OutcomeWait:
    """The polling policy of `follow_trajectory`: long polls until the outcome or `timeout`."""

    def __init__(self, traj_id: int, timeout: float | None) -> None:
        self.id = traj_id
        self.timeout = timeout
        self.deadline = None if timeout is None else time.monotonic() + timeout

    def call(self) -> Call:
        """The next long poll (at most MAX_WAIT_S, never past the deadline)."""
        wait = MAX_WAIT_S
        if self.deadline is not None:
            wait = max(0.001, min(wait, self.deadline - time.monotonic()))
        return by_id_call(self.id, wait)

    def finished(self, status: TrajectoryStatus) -> bool:
        """True: return `status`. TimeoutError once the deadline passed with it running."""
        if status.done:
            return True
        if self.deadline is not None and time.monotonic() >= self.deadline:
            raise TimeoutError(
                f"trajectory {self.id} still running after {self.timeout} s "
                f"(progress {status.progress:.0%})"
            )
        return False
