"""Judge: every simulation_interfaces call, as a ROS 2 user makes it (run through judge.py)."""

from __future__ import annotations

import rclpy
from common import out, spin_until
from rclpy.node import Node


def call_service(node, kind, name, **fields):
    """One service call from `node`, waiting for the server and the reply."""
    client = node.create_client(kind, name)
    assert client.wait_for_service(timeout_sec=60), name  # a loaded box discovers slowly
    req = kind.Request()
    for k, v in fields.items():
        setattr(req, k, v)
    fut = client.call_async(req)
    rclpy.spin_until_future_complete(node, fut, timeout_sec=30)
    return fut.result()


def sim(ns: str, reset_ns: str) -> None:
    """Every simulation_interfaces call: global ones at the root, entity ones in `ns`, a
    world's reset in `reset_ns`."""
    from rclpy.action import ActionClient
    from rosgraph_msgs.msg import Clock
    from simulation_interfaces import srv
    from simulation_interfaces.action import SimulateSteps
    from simulation_interfaces.msg import SimulationState

    node = Node("judge_sim")
    clock: list = []
    node.create_subscription(Clock, "/clock", lambda m: clock.append(m.clock), 10)

    def call(kind, name, **fields):
        return call_service(node, kind, name, **fields)

    def now() -> float:
        n = len(clock)
        spin_until(node, lambda: len(clock) > n, 2)
        spin_until(node, lambda: False, 0.3)  # the frame of the last tick
        c = clock[-1]
        return c.sec + c.nanosec * 1e-9

    def state(value: int):
        s = SimulationState()
        s.state = value
        return s

    r: dict = {}
    feats = call(srv.GetSimulatorFeatures, "/get_simulator_features").features
    r["features"] = list(feats.features)
    r["custom_info"] = feats.custom_info
    r["state0"] = call(srv.GetSimulationState, "/get_simulation_state").state.state
    r["step_playing"] = call(srv.StepSimulation, "/step_simulation", steps=1).result.result
    r["pause"] = call(srv.SetSimulationState, "/set_simulation_state", state=state(2)).result.result
    r["pause_again"] = call(
        srv.SetSimulationState, "/set_simulation_state", state=state(2)
    ).result.result
    r["state_paused"] = call(srv.GetSimulationState, "/get_simulation_state").state.state
    t0 = now()
    r["step5"] = call(srv.StepSimulation, "/step_simulation", steps=5).result.result
    t1 = now()
    steps = ActionClient(node, SimulateSteps, "/simulate_steps")
    assert steps.wait_for_server(timeout_sec=20)
    goal = SimulateSteps.Goal()
    goal.steps = 10
    feedback: list = []
    fut = steps.send_goal_async(
        goal, feedback_callback=lambda f: feedback.append(f.feedback.completed_steps)
    )
    rclpy.spin_until_future_complete(node, fut, timeout_sec=20)
    rf = fut.result().get_result_async()
    rclpy.spin_until_future_complete(node, rf, timeout_sec=30)
    t2 = now()
    r["simulate"] = {
        "status": rf.result().status,
        "result": rf.result().result.result.result,
        "feedback": feedback,
    }
    r["clock"] = [t0, t1, t2]
    r["play"] = call(srv.SetSimulationState, "/set_simulation_state", state=state(1)).result.result
    r["state_playing"] = call(srv.GetSimulationState, "/get_simulation_state").state.state
    r["entities"] = list(call(srv.GetEntities, f"{ns}/get_entities").entities)
    filt = srv.GetEntities.Request().filters
    filt.filter = "^wrist"
    r["wrists"] = list(call(srv.GetEntities, f"{ns}/get_entities", filters=filt).entities)
    cube = call(srv.GetEntityState, f"{ns}/get_entity_state", entity="cube")
    p, q = cube.state.pose.position, cube.state.pose.orientation
    r["cube"] = {
        "result": cube.result.result,
        "frame": cube.state.header.frame_id,
        "pose": [p.x, p.y, p.z, q.w, q.x, q.y, q.z],
    }
    r["missing"] = call(srv.GetEntityState, f"{ns}/get_entity_state", entity="nope").result.result
    many = call(srv.GetEntitiesStates, f"{ns}/get_entities_states")
    r["states"] = {
        n: [s.pose.position.x, s.pose.position.y, s.pose.position.z]
        for n, s in zip(many.entities, many.states, strict=True)
    }
    r["set_entity"] = call(
        srv.SetEntityState, f"{ns}/set_entity_state", entity="wrist_3_link"
    ).result.result
    r["reset_time"] = call(
        srv.ResetSimulation, f"{reset_ns}/reset_simulation", scope=1
    ).result.result
    r["reset_state"] = call(
        srv.ResetSimulation, f"{reset_ns}/reset_simulation", scope=2
    ).result.result
    out(**r)


def entity(ns: str) -> None:
    """SetEntityState as a ROS user places a body: paused, the cube set in `ns` (pose and a
    world-frame spin), read back at once (the standard's "instant change"), one step, read
    back; then a set of an unknown entity, read again."""
    from simulation_interfaces import srv
    from simulation_interfaces.msg import EntityState, SimulationState

    node = Node("judge_entity")

    def call(kind, name, **fields):
        return call_service(node, kind, name, **fields)

    def get() -> dict:
        s = call(srv.GetEntityState, f"{ns}/get_entity_state", entity="cube").state
        p, q, a = s.pose.position, s.pose.orientation, s.twist.angular
        return {
            "pose": [p.x, p.y, p.z, q.w, q.x, q.y, q.z],
            "angular": [a.x, a.y, a.z],
            "stamp": s.header.stamp.sec + s.header.stamp.nanosec * 1e-9,
        }

    paused = SimulationState()
    paused.state = SimulationState.STATE_PAUSED
    r: dict = {"pause": call(srv.SetSimulationState, "/set_simulation_state", state=paused)}
    r["pause"] = r["pause"].result.result
    st = EntityState()
    st.pose.position.x, st.pose.position.y, st.pose.position.z = 0.3, -0.5, 1.2
    h = 0.5**0.5  # 90 degrees about x
    st.pose.orientation.w, st.pose.orientation.x = h, h
    st.pose.orientation.y = st.pose.orientation.z = 0.0
    st.twist.angular.z = 1.0
    done = call(srv.SetEntityState, f"{ns}/set_entity_state", entity="cube", state=st)
    r["set"] = done.result.result
    r["instant"] = get()  # no step between: the set is in effect already
    r["step"] = call(srv.StepSimulation, "/step_simulation", steps=1).result.result
    r["got"] = get()
    missing = call(srv.SetEntityState, f"{ns}/set_entity_state", entity="sphere", state=st)
    r["missing"] = [missing.result.result, missing.result.error_message]
    st.pose.position.z = float("nan")
    nan = call(srv.SetEntityState, f"{ns}/set_entity_state", entity="cube", state=st)
    r["nan"] = [nan.result.result, nan.result.error_message]
    st.pose.position.z = 9.0
    high = call(srv.SetEntityState, f"{ns}/set_entity_state", entity="cube", state=st)
    r["high"] = [high.result.result, high.result.error_message]
    r["after"] = get()
    many = call(srv.GetEntitiesStates, f"{ns}/get_entities_states")
    cube = many.states[list(many.entities).index("cube")]
    r["many_angular"] = [cube.twist.angular.x, cube.twist.angular.y, cube.twist.angular.z]
    out(**r)


def states(values: list[int]) -> None:
    """SetSimulationState to each of `values` in turn (0 STOPPED, 1 PLAYING, 2 PAUSED,
    3 QUITTING), as a harness starts and ends episodes: each answer (result, error message)
    and the state GetSimulationState reports after it."""
    from simulation_interfaces import srv
    from simulation_interfaces.msg import SimulationState

    node = Node("judge_states")
    steps = []
    for value in values:
        want = SimulationState()
        want.state = value
        res = call_service(node, srv.SetSimulationState, "/set_simulation_state", state=want)
        now = call_service(node, srv.GetSimulationState, "/get_simulation_state").state.state
        steps.append({"result": [res.result.result, res.result.error_message], "state": now})
    out(steps=steps)
