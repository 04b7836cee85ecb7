"""Judges under load (run through judge.py): round trips, a 1000/s flood, the Isaac contract."""

from __future__ import annotations

import time

import rclpy
from common import JOINTS, out, spin_until
from rclpy.node import Node


def latency(worlds: int, rounds: int, gap: float) -> None:
    """publish → first /world_N/joint_states showing the joint move toward the new target
    (>= 1e-4 rad), one world at a time, `gap` s between rounds (the arm at rest each time).
    Also `ready_s`: from the judge's publishers and subscriptions made to every one of them
    matched and publishing states (for a namespace not used before: its opening included)."""
    from sensor_msgs.msg import JointState

    t_made = time.perf_counter()
    node = Node("judge_latency")
    latest: dict = {}
    pubs = {}
    for w in range(worlds):
        pubs[w] = node.create_publisher(JointState, f"/world_{w}/joint_commands", 10)
        node.create_subscription(
            JointState,
            f"/world_{w}/joint_states",
            lambda m, w=w: latest.__setitem__(w, (time.perf_counter(), m.position[2])),
            10,
        )
    spin_until(
        node,
        lambda: len(latest) == worlds and all(p.get_subscription_count() for p in pubs.values()),
        60,
    )
    ready_s = time.perf_counter() - t_made
    spin_until(node, lambda: False, 1.0)
    out_ms = []
    for i in range(rounds):
        w = i % worlds
        before = latest[w][1]
        target = before + (0.05 if (i // worlds) % 2 == 0 else -0.05)
        sign = 1.0 if target > before else -1.0
        msg = JointState()
        msg.name, msg.position = ["elbow_joint"], [target]
        t0 = time.perf_counter()
        pubs[w].publish(msg)
        moved = spin_until(
            node,
            lambda w=w, t0=t0, before=before, sign=sign: (
                latest[w][0] > t0 and sign * (latest[w][1] - before) >= 1e-4
            ),
            5,
        )
        if moved:
            out_ms.append((latest[w][0] - t0) * 1e3)
        spin_until(node, lambda: False, gap)  # each world rests again before its next round
    out(ms=out_ms, rounds=rounds, ready_s=ready_s)


def flood(worlds: int, rate: float, seconds: float) -> None:
    """`rate` JointState commands/s spread over /world_0..N-1/joint_commands."""
    from sensor_msgs.msg import JointState

    node = Node("judge_flood")
    pubs = [
        node.create_publisher(JointState, f"/world_{w}/joint_commands", 100) for w in range(worlds)
    ]
    spin_until(node, lambda: all(p.get_subscription_count() for p in pubs), 60)
    spin_until(node, lambda: False, 1.0)
    n = int(rate * seconds)
    t0 = time.perf_counter()
    last = {}
    for i in range(n):
        w = i % worlds
        value = round(0.001 * (i % 500), 3)
        msg = JointState()
        msg.name, msg.position = ["finger_joint"], [value]
        pubs[w].publish(msg)
        last[w] = value
        delay = t0 + (i + 1) / rate - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    wall = time.perf_counter() - t0
    spin_until(node, lambda: False, 2.0)
    out(sent=n, wall=wall, last={str(k): v for k, v in last.items()})


def isaac(rate: float, seconds: float) -> None:
    """topic_based_ros2_control's side of the Isaac contract: full JointState commands on
    /isaac_joint_commands at `rate`, states read back on /isaac_joint_states."""
    from sensor_msgs.msg import JointState

    node = Node("judge_isaac")
    pub = node.create_publisher(JointState, "/isaac_joint_commands", 10)
    states: list = []
    node.create_subscription(  # a deep queue: a judge descheduled on a busy box drops nothing
        JointState, "/isaac_joint_states", lambda m: states.append(time.perf_counter()), 200
    )
    spin_until(node, lambda: pub.get_subscription_count() and states, 30)
    n = int(rate * seconds)
    t0 = time.perf_counter()
    n_states = len(states)
    for i in range(n):
        msg = JointState()
        msg.name = list(JOINTS)
        msg.position = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0, 0.3 * i / n]
        msg.velocity = [0.0] * 7
        pub.publish(msg)
        rclpy.spin_once(node, timeout_sec=0)
        delay = t0 + (i + 1) / rate - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    wall = time.perf_counter() - t0
    got = len(states) - n_states
    spin_until(node, lambda: False, 1.0)
    out(sent=n, wall=wall, states_per_s=got / wall, last=0.3 * (n - 1) / n)
