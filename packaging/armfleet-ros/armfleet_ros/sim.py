"""ROS 2 `simulation_interfaces` (the standard Isaac Sim 5+, Gazebo and O3DE implement) on
armfleet's API.

Global, once (root namespace): `get_simulator_features`, `get_simulation_state`,
`set_simulation_state` (PLAYING = the `play_mode` parameter, realtime or fast; PAUSED; STOPPED =
paused and every world reset), `step_simulation` and the `simulate_steps` action (paused only;
one control tick per step, feedback per step), `reset_simulation` (every world).
Per world namespace: `reset_simulation` (that world), `get_entities`, `get_entity_state`,
`get_entities_states` (the robot's links, world-frame poses from MuJoCo; and the scene's free
bodies, pose and world-frame twist from armfleet's entity API; acceleration is not reported),
`set_entity_state` (a free body's pose and twist, from armfleet's next tick: entities.py).
"""

from __future__ import annotations

import re
from typing import Any

from rclpy.action import ActionServer, CancelResponse
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import Result, SimulationState, SimulatorFeatures
from simulation_interfaces.srv import (
    GetEntities,
    GetEntitiesStates,
    GetEntityState,
    GetSimulationState,
    GetSimulatorFeatures,
    ResetSimulation,
    SetEntityState,
    SetSimulationState,
    StepSimulation,
)
from websockets.sync.client import connect

from armfleet_ros import auth, entities
from armfleet_ros.link import Poses
from armfleet_ros.params import param
from clients import ros_rules, stream
from clients.errors import ArmfleetError, Conflict
from clients.wire import POSE_MAGIC

F = SimulatorFeatures
FEATURES = [
    F.SIMULATION_RESET,
    F.SIMULATION_RESET_STATE,
    F.SIMULATION_STATE_GETTING,
    F.SIMULATION_STATE_SETTING,
    F.SIMULATION_STATE_PAUSE,
    F.STEP_SIMULATION_SINGLE,
    F.STEP_SIMULATION_MULTIPLE,
    F.STEP_SIMULATION_ACTION,
    F.ENTITY_STATE_GETTING,
    F.ENTITY_STATE_SETTING,
]
INFO = (
    "armfleet: many UR10e + Robotiq 2F-140 worlds, one per /world_N namespace (world 0 also at "
    "the root). PLAYING runs in the node's play_mode (realtime or fast). A step is one control "
    "tick. Resets put worlds back to home; simulated time keeps counting. Entity states carry "
    "world-frame poses; free bodies (the scene's entities) also their world-frame twist, and only "
    "they can be set (pose and twist, from the next tick). No acceleration (zeros)."
)


_result = entities.result


class GlobalSim:
    """The services and the action that act on the whole simulation."""

    def __init__(self, owner: Any, part: Any) -> None:
        self.owner = owner
        node, group = part.servers, part.group
        self.play_mode = str(param(owner.node, "play_mode", "realtime"))
        if self.play_mode not in ("realtime", "fast"):
            raise ValueError(f"play_mode must be realtime or fast, got {self.play_mode!r}")
        srv = node.create_service
        srv(GetSimulatorFeatures, "/get_simulator_features", self._features, callback_group=group)
        srv(GetSimulationState, "/get_simulation_state", self._get_state, callback_group=group)
        srv(SetSimulationState, "/set_simulation_state", self._set_state, callback_group=group)
        srv(StepSimulation, "/step_simulation", self._step, callback_group=group)
        srv(ResetSimulation, "/reset_simulation", self._reset, callback_group=group)
        self.steps = ActionServer(
            node,
            SimulateSteps,
            "/simulate_steps",
            execute_callback=self._simulate,
            cancel_callback=lambda _h: CancelResponse.ACCEPT,
            callback_group=group,
        )

    def _mode(self) -> str:
        return self.owner.http.info().mode

    def _features(self, _req: Any, res: Any) -> Any:
        res.features.features = list(FEATURES)
        res.features.custom_info = INFO
        return res

    def _get_state(self, _req: Any, res: Any) -> Any:
        try:
            mode = self._mode()
        except ArmfleetError as exc:
            return _result(res, Result.RESULT_OPERATION_FAILED, str(exc))
        paused = mode == "paused"
        res.state.state = SimulationState.STATE_PAUSED if paused else SimulationState.STATE_PLAYING
        return _result(res, Result.RESULT_OK)

    def _set_state(self, req: Any, res: Any) -> Any:
        want = req.state.state
        http = self.owner.http
        try:
            mode = self._mode()
            if want == SimulationState.STATE_PLAYING:
                if mode == self.play_mode:
                    return _result(res, SetSimulationState.Response.ALREADY_IN_TARGET_STATE)
                http.set_mode(self.play_mode)
            elif want == SimulationState.STATE_PAUSED:
                if mode == "paused":
                    return _result(res, SetSimulationState.Response.ALREADY_IN_TARGET_STATE)
                http.pause()
                self.owner.catch_up()
            elif want == SimulationState.STATE_STOPPED:
                http.pause()
                http.reset()
                self.owner.catch_up()
            else:
                text = f"state {want} is not one armfleet can be put in (playing, paused, stopped)"
                return _result(res, Result.RESULT_FEATURE_UNSUPPORTED, text)
        except ArmfleetError as exc:
            return _result(res, SetSimulationState.Response.STATE_TRANSITION_ERROR, str(exc))
        return _result(res, Result.RESULT_OK)

    def _step(self, req: Any, res: Any) -> Any:
        if req.steps < 1:
            return _result(res, Result.RESULT_OPERATION_FAILED, "steps must be at least 1")
        try:
            self.owner.http.step(int(req.steps))
        except Conflict as exc:  # not paused
            return _result(res, Result.RESULT_INCORRECT_STATE, str(exc))
        except ArmfleetError as exc:
            return _result(res, Result.RESULT_OPERATION_FAILED, str(exc))
        self.owner.catch_up()
        return _result(res, Result.RESULT_OK)

    def _reset(self, req: Any, res: Any) -> Any:
        return reset(self.owner, None, req, res)

    def _simulate(self, handle: Any) -> Any:
        total = int(handle.request.steps)
        result = SimulateSteps.Result()
        for done in range(1, total + 1):
            if handle.is_cancel_requested:
                handle.canceled()
                return _result(result, Result.RESULT_OK, f"cancelled after {done - 1} steps")
            try:
                self.owner.http.step(1)
            except Conflict as exc:
                handle.abort()
                return _result(result, Result.RESULT_INCORRECT_STATE, str(exc))
            except ArmfleetError as exc:
                handle.abort()
                return _result(result, Result.RESULT_OPERATION_FAILED, str(exc))
            self.owner.catch_up()
            fb = SimulateSteps.Feedback()
            fb.completed_steps, fb.remaining_steps = done, total - done
            handle.publish_feedback(fb)
        handle.succeed()
        return _result(result, Result.RESULT_OK)


def reset(owner: Any, world: Any, req: Any, res: Any) -> Any:
    """ResetSimulation for every world (`world` None) or one: SCOPE_STATE and DEFAULT/ALL put
    worlds back to home; time alone, or spawned entities alone, cannot be reset."""
    scope = req.scope
    if scope not in (req.SCOPE_DEFAULT, req.SCOPE_ALL) and not scope & req.SCOPE_STATE:
        text = "only the state scope resets (armfleet's simulated time keeps counting)"
        return _result(res, Result.RESULT_FEATURE_UNSUPPORTED, text)
    try:
        owner.http.reset(world)
    except ArmfleetError as exc:
        return _result(res, Result.RESULT_OPERATION_FAILED, str(exc))
    return _result(res, Result.RESULT_OK)


# the per-world services (namespaces.py opens them together, on the first use of any)
WORLD_SERVICES = (
    "reset_simulation",
    "get_entities",
    "get_entity_state",
    "get_entities_states",
    "set_entity_state",
)


class WorldSim:
    """The entity services of one world namespace (and its own reset)."""

    def __init__(self, owner: Any, world: int, ns: str, part: Any) -> None:
        self.owner, self.world = owner, world
        node, group = part.servers, part.group
        self.bodies = {b["name"]: b["id"] for b in owner.frames["bodies"]}
        self.free = list(owner.free_bodies)  # the same scene in every world (read at start)
        self.bodies |= {name: -1 for name in self.free if name not in self.bodies}
        srv = node.create_service
        if ns:  # the root's reset_simulation is the global one
            srv(ResetSimulation, f"{ns}/reset_simulation", self._reset, callback_group=group)
        srv(GetEntities, f"{ns}/get_entities", self._entities, callback_group=group)
        srv(GetEntityState, f"{ns}/get_entity_state", self._state, callback_group=group)
        srv(GetEntitiesStates, f"{ns}/get_entities_states", self._states, callback_group=group)
        srv(SetEntityState, f"{ns}/set_entity_state", self._set, callback_group=group)

    def _reset(self, req: Any, res: Any) -> Any:
        return reset(self.owner, self.world, req, res)

    def _matching(self, pattern: str) -> list[str]:
        if not pattern:
            return list(self.bodies)
        rx = re.compile(pattern)
        return [name for name in self.bodies if rx.search(name)]

    def _entities(self, req: Any, res: Any) -> Any:
        try:
            res.entities = self._matching(req.filters.filter)
        except re.error as exc:
            return _result(res, Result.RESULT_OPERATION_FAILED, f"filter: {exc}")
        return _result(res, Result.RESULT_OK)

    def _poses(self) -> Poses:
        """This world's body poses now: one frame of the pose socket."""
        url = stream.ws_url(self.owner.url, None).replace("/v1/ws", "/v1/ws/view", 1)
        url += ("&" if "?" in url else "?") + f"worlds={self.world}"
        with connect(
            url,
            max_size=stream.MAX_SIZE,
            proxy=None,
            open_timeout=10,
            additional_headers=auth.headers(),
        ) as ws:
            while True:
                data = ws.recv(timeout=10)
                if isinstance(data, bytes) and data[:4] == POSE_MAGIC:
                    return Poses(data)

    def _fill(self, state: Any, poses: Poses, name: str) -> None:
        row = poses.poses[poses.row[self.world], self.bodies[name]]
        state.header.frame_id = "world"
        state.header.stamp.sec, state.header.stamp.nanosec = ros_rules.stamp(
            poses.tick * self.owner.tick_dt
        )
        p, q = state.pose.position, state.pose.orientation
        p.x, p.y, p.z = (float(v) for v in row[:3])
        q.w, q.x, q.y, q.z = (float(v) for v in row[3:])

    def _state(self, req: Any, res: Any) -> Any:
        if req.entity not in self.bodies:
            return _result(res, Result.RESULT_NOT_FOUND, f"no entity {req.entity!r}")
        try:
            if req.entity in self.free:
                got = self.owner.http.entity(self.world, req.entity)
                entities.fill(res.state, got, got["tick"], self.owner.tick_dt)
            else:
                self._fill(res.state, self._poses(), req.entity)
        except (OSError, ArmfleetError, *stream.LOST) as exc:
            return _result(res, Result.RESULT_OPERATION_FAILED, str(exc))
        return _result(res, Result.RESULT_OK)

    def _states(self, req: Any, res: Any) -> Any:
        from simulation_interfaces.msg import EntityState

        try:
            names = self._matching(req.filters.filter)
            poses = self._poses()
            free = self.owner.http.entities(self.world) if self.free else {"entities": []}
        except re.error as exc:
            return _result(res, Result.RESULT_OPERATION_FAILED, f"filter: {exc}")
        except (OSError, ArmfleetError, *stream.LOST) as exc:
            return _result(res, Result.RESULT_OPERATION_FAILED, str(exc))
        res.entities = names
        by_name = {e["name"]: e for e in free["entities"]}
        states = []
        for name in names:
            st = EntityState()
            if name in by_name:
                entities.fill(st, by_name[name], free["tick"], self.owner.tick_dt)
            else:
                self._fill(st, poses, name)
            states.append(st)
        res.states = states
        return _result(res, Result.RESULT_OK)

    def _set(self, req: Any, res: Any) -> Any:
        return entities.set_state(self.owner.http, self.world, self.free, req, res)
