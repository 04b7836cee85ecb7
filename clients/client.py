"""Blocking client: `ArmfleetClient` (httpx) and `WorldSession` (websockets.sync).

    with ArmfleetClient("http://127.0.0.1:8000") as arm:
        arm.wait_ready(60)
        arm.increment(0, "elbow_joint", 0.1)
        for state in arm.stream(0, rate=10):
            print(state.tick, state.position)

A world of a shared server, for as long as the block runs (reset to home, given back after):

    with ArmfleetClient(url, token=TOKEN).lease(label="ci") as mine:
        mine.increment(mine.leased.world, "elbow_joint", 0.1)

The asynchronous twin, with the same methods, is `clients.async_client.AsyncArmfleetClient`.
Both only do the I/O: requests and replies are built and read in `clients.calls`, WebSocket
frames and the reconnect policy in `clients.stream`.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import httpx
from websockets.sync.client import ClientConnection
from websockets.sync.client import connect as ws_connect

from clients import calls, cartesian, cell, models, stream
from clients import trajectory as tj
from clients.calls import DEFAULT_TIMEOUT, Call
from clients.errors import Unreachable
from clients.models import JointRef, WorldSpec

if TYPE_CHECKING:  # typing has both from 3.11 on; the client also runs on 3.10
    from typing_extensions import Self, Unpack


class _Closes:
    """`with thing:` closes the thing at the end."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ArmfleetClient(_Closes, cartesian.Calls, calls.Endpoint):
    """REST + WebSocket client for one armfleet service. Thread-safe for HTTP calls."""

    HTTP = httpx.Client

    def call(self, call: Call) -> Any:
        try:
            reply = self._http.request(call.method, call.path, **call.request_kwargs(self.timeout))
        except httpx.TransportError as exc:
            raise calls.transport_error(self.url, exc) from exc
        return call.result(reply)

    def close(self) -> None:
        self._http.close()

    # -- REST --------------------------------------------------------------------------------

    def info(self) -> models.Info:
        """The robot (joint names, limits, home), batch size, device, mode and speed."""
        return self.call(calls.info_call())

    def state(self, world: int, entities: bool = False) -> models.WorldState:
        """One world; `entities=True`: its entities' pose and twist of the same tick too."""
        return self.call(calls.state_call(world, entities))

    def states(self, worlds: WorldSpec = None, entities: bool = False) -> models.BatchStates:
        """Several worlds (None: all; or [0, 3], or "0-63") as column arrays; `entities=True`:
        their entities of the same tick too (`BatchStates.entities`)."""
        return self.call(calls.states_call(worlds, entities))

    def increment(self, world: int, joint: JointRef, delta: float) -> models.CommandAck:
        """Add `delta` [rad] to one joint's target (the seed's Up/Down buttons)."""
        return self.call(calls.increment_call(world, joint, delta))

    def set_targets(self, world: int, targets: Mapping[JointRef, float]) -> models.CommandAck:
        """Set some joints' targets, e.g. {"finger_joint": 0.7}; the others keep theirs."""
        return self.call(calls.set_targets_call(world, targets))

    def set_many(self, worlds: Iterable[int], positions: Any) -> models.BatchAck:
        """Full 7-joint targets for many worlds, applied at one tick; positions is (n, 7)."""
        return self.call(calls.set_many_call(worlds, positions))

    def reset(self, world: int | Iterable[int] | None = None) -> models.ResetResult:
        """Reset one world, a list of worlds, or (None) all worlds to home."""
        return self.call(calls.reset_call(world))

    def trigger_protective_stop(self, world: int) -> models.SafetyAck:
        """Protective-stop the world now (ur_rtde's triggerProtectiveStop): its arm is held
        where it is and commands that would move it are refused (Conflict) until
        `unlock_protective_stop` (5 s after the stop at the earliest) or a reset."""
        return self.call(calls.trigger_protective_stop_call(world))

    def unlock_protective_stop(self, world: int) -> models.SafetyAck:
        """Back to NORMAL, as UR's Dashboard `unlock protective stop`: Conflict within 5 s of
        the stop (the robot's rule); the arm stays where the stop held it."""
        return self.call(calls.unlock_protective_stop_call(world))

    # -- entities and physics parameters (calls: clients.cell) -----------------------------

    def entities(self, world: int) -> dict[str, Any]:
        """Pose and twist of every entity (named free body) of one world, and the tick."""
        return self.call(cell.entities_call(world))

    def entity(self, world: int, name: str) -> dict[str, Any]:
        return self.call(cell.entity_call(world, name))

    def set_entity(self, world: int, name: str, **values: Any) -> dict[str, Any]:
        """Any of position, orientation (w x y z), linear, angular; from the next tick."""
        return self.call(cell.set_entity_call(world, name, **values))

    def set_entities(self, writes: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
        """Entity writes of many worlds ({"world", "name", ...}), all at one tick."""
        return self.call(cell.set_entities_call(writes))

    def param_table(self) -> dict[str, Any]:
        """The parameters a world may have of its own, with units and ranges."""
        return self.call(cell.param_table_call())

    def params(self, world: int) -> dict[str, Any]:
        return self.call(cell.params_call(world))

    def set_params(self, world: int, params: Mapping[str, Any]) -> dict[str, Any]:
        """E.g. {"cube.mass": 0.3, "payload": [1.0, 0, 0, 0.05]}; from the next tick."""
        return self.call(cell.set_params_call(world, params))

    def set_params_many(self, writes: Iterable[tuple[int, Mapping[str, Any]]]) -> dict[str, Any]:
        """(world, params) pairs, all at one tick."""
        return self.call(cell.set_params_many_call(writes))

    def randomize(
        self, seed: int, spec: Mapping[str, Any], worlds: Iterable[int] | None = None
    ) -> dict[str, Any]:
        """Reset worlds (None: all) with entity poses and parameters drawn from `spec` with
        `seed` (the same seed, the same worlds); the reply names the tick, seed and spec."""
        return self.call(cell.randomize_call(seed, spec, worlds))

    def randomization(self, world: int) -> dict[str, Any]:
        """A world's last randomisation (seed, spec, randomized_at; null when none), kept
        through snapshots and restores."""
        return self.call(cell.randomization_call(world))

    # -- trajectories (bodies and calls: clients.trajectory) ---------------------------------

    def start_trajectory(
        self, world: int, joint_names: Sequence[str], points: Iterable[Any], **options: Any
    ) -> tj.TrajectoryStarted:
        """Follow a JointTrajectory (`tj.point(...)`s); options: path_tolerance, goal_tolerance
        (`tj.tolerance(...)`s), goal_time_tolerance [s]. Replaces a running one."""
        body = tj.trajectory_body(joint_names, points, **options)
        return self.call(tj.start_call(world, body))

    def start_trajectories(
        self, worlds: WorldSpec, joint_names: Sequence[str], points: Iterable[Any], **options: Any
    ) -> tj.TrajectoriesStarted:
        """One trajectory on many worlds (ids, or "0-9999"), all from the same tick."""
        body = tj.trajectory_body(joint_names, points, **options)
        return self.call(tj.start_many_call(worlds, body))

    def trajectory(self, world: int, wait: float = 0.0) -> tj.TrajectoryStatus:
        """The world's running (else last) trajectory; `wait` s for its outcome at most."""
        return self.call(tj.status_call(world, wait))

    def cancel_trajectory(self, world: int) -> tj.TrajectoryStatus:
        """Stop the world's trajectory; it holds where it was (Conflict if none runs)."""
        return self.call(tj.cancel_call(world))

    def wait_trajectory(self, traj_id: int, timeout: float | None = None) -> tj.TrajectoryStatus:
        """Block until the trajectory succeeds or aborts; TimeoutError after `timeout` s."""
        wait = tj.OutcomeWait(traj_id, timeout)
        while not wait.finished(status := self.call(wait.call())):
            pass
        return status

    def follow_trajectory(
        self,
        world: int,
        joint_names: Sequence[str],
        points: Iterable[Any],
        timeout: float | None = None,
        **options: Any,
    ) -> tj.TrajectoryStatus:
        """start_trajectory, then wait for its outcome (`.succeeded`, else `.reason`)."""
        started = self.start_trajectory(world, joint_names, points, **options)
        return self.wait_trajectory(started.id, timeout)

    def pause(self) -> models.SimStatus:
        return self.call(calls.pause_call())

    def resume(self) -> models.SimStatus:
        return self.call(calls.resume_call())

    def set_mode(self, mode: str) -> models.SimStatus:
        return self.call(calls.set_mode_call(mode))

    def step(self, n: int = 1) -> models.SimStatus:
        """Paused only: advance exactly n ticks; returns once they are done."""
        return self.call(calls.step_call(n))

    def ready(self) -> bool:
        try:
            self.call(calls.readyz_call())
        except calls.NOT_YET:
            return False
        return True

    def wait_ready(self, timeout: float = 60.0, poll: float = 0.2) -> None:
        """Block until /readyz says ready; NotReady (with the last reason) after `timeout`."""
        wait = calls.ReadyWait(timeout)
        while True:
            try:
                self.call(calls.readyz_call())
                return
            except calls.NOT_YET as exc:
                wait.failed(exc)
            time.sleep(poll)

    def leases(self) -> list[models.Lease]:
        """Every lease (the administrator's token), or this lease token's own."""
        return self.call(calls.leases_call())

    def renew_lease(self, ttl_s: float = 600.0) -> models.Lease:
        """This client's lease lives `ttl_s` more seconds from now."""
        if self.leased is None:
            raise ValueError("this client holds no lease (use `with client.lease() as c:`)")
        return self.call(calls.renew_call(self.leased.id, ttl_s))

    # -- WebSocket ---------------------------------------------------------------------------

    def stream(
        self,
        worlds: WorldSpec,
        rate: float | None = None,
        **options: Unpack[stream.StreamOptions],
    ) -> Iterator[Any]:
        """Yield states from the WebSocket: WorldState for one world (an int), BatchStates for
        a list / range string / None (all).

        When the connection drops (server restart, network), reconnect with backoff and go on;
        `on_status` hears about each drop and reconnect. `reconnect=False` raises Unreachable
        instead; `give_up_after` seconds of failing in a row raise it too. An unknown world
        raises NotFound at once. `binary=True` asks batch streams for float32 frames (same
        BatchStates, a fraction of the bytes and parse time). `entities=True`: every state
        carries its worlds' entities (`.entities`, pose and twist of the same tick).
        """
        policy = stream.Reconnector.for_stream(self.url, worlds, rate, options)
        while True:
            try:
                with _open(policy.url, self.timeout, self.token) as ws:
                    policy.opened()
                    for text in ws:
                        if (msg := policy.frame(text)) is not None:
                            yield msg
                    reason = stream.close_reason(ws.close_code, ws.close_reason)
            except stream.LOST as exc:
                reason = stream.reason_for(exc)
            time.sleep(policy.dropped(reason))

    def connect(
        self, world: int, rate: float | None = None, entities: bool = False
    ) -> WorldSession:
        """Open a WebSocket to one world: send commands, get their acks, iterate states
        (`entities=True`: with the world's entities)."""
        url = stream.ws_url(self.url, world, rate, entities=entities)
        return WorldSession(url, world, self.timeout, self.token)


def _open(url: str, timeout: float, token: str | None = None) -> ClientConnection:
    with stream.bad_url():
        return ws_connect(url, **stream.connect_options(timeout, token))


class WorldSession(_Closes, stream.WorldLink, cartesian.WorldOps):
    """One world over one WebSocket: commands get their acks back (matched by id) and state
    frames that arrive meanwhile are kept for iteration. Does not reconnect: a command on a
    dropped socket raises Unreachable. Use from one thread at a time (a lock enforces it).

        with client.connect(0) as s:
            ack = s.increment("elbow_joint", 0.1)
            for state in s: ...
    """

    def __init__(
        self, url: str, world: int, timeout: float = DEFAULT_TIMEOUT, token: str | None = None
    ) -> None:
        super().__init__(url, world, timeout, token)
        self._states: deque[models.WorldState] = deque(maxlen=256)
        self._lock = threading.Lock()
        try:
            self._ws = _open(url, timeout, token).__enter__()  # closed by close()
        except stream.DROPPED as exc:
            raise stream.lost(url, exc) from exc

    def _recv(self, timeout: float | None) -> Any:
        try:
            msg = stream.parse(self._ws.recv(timeout))
        except TimeoutError:  # nothing came in time; the socket is fine (LOST has it too)
            raise TimeoutError(f"no message from {self.url} in {timeout:g} s") from None
        except stream.LOST as exc:
            raise stream.lost(self.url, exc) from exc
        if isinstance(msg, models.WorldState):
            self.latest = msg
        return msg

    def _command(self, msg_id: int, text: str) -> models.CommandAck:
        with self._lock:
            try:
                self._ws.send(text)
            except stream.LOST as exc:
                raise stream.lost(self.url, exc) from exc
            deadline = time.monotonic() + self.timeout
            while True:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no ack for command {msg_id} in {self.timeout} s")
                msg = self._recv(left)
                if isinstance(msg, models.WorldState):
                    self._states.append(msg)
                elif isinstance(msg, models.CommandAck | models.WsError) and msg.id == msg_id:
                    return stream.ack_or_raise(msg)

    def increment(self, joint: JointRef, delta: float) -> models.CommandAck:
        return self._command(*self._ids.increment(joint, delta))

    def set_targets(self, targets: Mapping[JointRef, float]) -> models.CommandAck:
        return self._command(*self._ids.set_targets(targets))

    def reset(self) -> models.CommandAck:
        return self._command(*self._ids.reset())

    def recv_state(self, timeout: float | None = None) -> models.WorldState:
        """The next state frame (buffered ones first); TimeoutError after `timeout`."""
        with self._lock:
            if self._states:
                return self._states.popleft()
            deadline = None if timeout is None else time.monotonic() + timeout
            while True:
                left = None if deadline is None else max(0.0, deadline - time.monotonic())
                msg = self._recv(left)
                if isinstance(msg, models.WorldState):
                    return msg

    def __iter__(self) -> Iterator[models.WorldState]:
        while True:
            try:
                yield self.recv_state()
            except Unreachable:
                return

    def close(self) -> None:
        self._ws.close()
