"""A world namespace opened by its first use (run through judge.py): what the armfleet node
has under it before, after a subscriber of its states, after an action client, after a
service client. The node's own endpoints are read per node (`ros2 node info`), so the judge's
own names never count as the node's."""

from __future__ import annotations

import time

from common import out, spin_until
from rclpy.node import Node


def _owned(node: Node, ns: str) -> dict:
    """The endpoints under `ns` of every `armfleet*` node: {kind: {name: types}}."""
    seen: dict = {"publishers": {}, "subscriptions": {}, "services": {}}
    calls = {
        "publishers": node.get_publisher_names_and_types_by_node,
        "subscriptions": node.get_subscriber_names_and_types_by_node,
        "services": node.get_service_names_and_types_by_node,
    }
    for name, space in node.get_node_names_and_namespaces():
        if not name.startswith("armfleet"):
            continue
        for kind, call in calls.items():
            for topic, types in call(name, space):
                if topic.startswith(ns + "/"):
                    seen[kind][topic] = list(types)
    return seen


def opening(ns: str) -> None:
    from control_msgs.action import GripperCommand
    from rclpy.action import ActionClient
    from sensor_msgs.msg import JointState
    from simulation_interfaces.srv import GetEntities

    node = Node("judge_open")
    spin_until(node, lambda: ("armfleet", "/") in node.get_node_names_and_namespaces(), 60)
    spin_until(node, lambda: False, 2.0)  # the node's endpoints discovered, if it had any
    report: dict = {"before": _owned(node, ns)}

    t0, states = time.perf_counter(), []
    node.create_subscription(JointState, f"{ns}/joint_states", states.append, 10)
    spin_until(node, lambda: states, 60)
    report["state_s"] = time.perf_counter() - t0
    report["state_names"] = list(states[0].name) if states else None
    spin_until(node, lambda: False, 1.0)
    report["topics"] = _owned(node, ns)

    t0 = time.perf_counter()
    grip = ActionClient(node, GripperCommand, f"{ns}/robotiq_gripper_controller/gripper_cmd")
    report["action_ready"] = grip.wait_for_server(timeout_sec=60)
    report["action_s"] = time.perf_counter() - t0
    spin_until(node, lambda: False, 1.0)
    report["action"] = _owned(node, ns)

    t0 = time.perf_counter()
    client = node.create_client(GetEntities, f"{ns}/get_entities")
    report["service_ready"] = client.wait_for_service(timeout_sec=60)
    report["service_s"] = time.perf_counter() - t0
    fut = client.call_async(GetEntities.Request())
    spin_until(node, fut.done, 30)
    report["entities"] = list(fut.result().entities) if fut.done() else None
    spin_until(node, lambda: False, 1.0)
    report["sim"] = _owned(node, ns)
    out(**report)
