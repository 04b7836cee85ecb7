"""Judges under load (run through judge.py): round trips, a 1000/s flood, the Isaac contract."""

from __future__ import annotations

import sys
import threading
import time

import rclpy
from common import JOINTS, out, spin_until
from rclpy.node import Node

REST = 0.002  # rad/s: the elbow moves less than 1e-4 rad in a tick, a round's threshold


class _Latest:
    """Each world's newest state (arrival, elbow position, elbow velocity), written by the
    executor's thread as states arrive; the rounds wait on it."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.of: dict = {}

    def put(self, w: int, msg) -> None:
        t = time.perf_counter()  # the arrival, as the callback sees it
        with self.cond:
            self.of[w] = (t, msg.position[2], msg.velocity[2])
            self.cond.notify_all()

    def until(self, pred, timeout: float) -> bool:
        end = time.monotonic() + timeout
        with self.cond:
            while not pred():
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self.cond.wait(min(left, 0.05))  # also: counts that change unannounced
        return True


def latency(worlds: int) -> None:
    """Round trips on demand: the bench writes rounds on stdin, `world sign delay_s` a line,
    and gets one JSON line a round. A round: the world's arm at rest, then its next state (the
    phase reference: states follow ticks), `delay_s` later a JointState on its
    joint_commands moving the elbow 0.05 rad by `sign`, and the time from that publish to the
    first /world_N/joint_states showing the elbow moved toward it (>= 1e-4 rad). The bench
    measures its direct path the same way (bench/ros_bench.py). States are taken by an
    executor spinning in a thread of its own, between rounds too (an unspun queue would hand
    old states over as new). First line: `ready_s`, from the judge's publishers and
    subscriptions made to all of them matched and publishing states (for a namespace not used
    before: its opening included)."""
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    t_made = time.perf_counter()
    node = Node("judge_latency")
    latest = _Latest()
    pubs = {}
    for w in range(worlds):
        pubs[w] = node.create_publisher(JointState, f"/world_{w}/joint_commands", 10)
        node.create_subscription(
            JointState, f"/world_{w}/joint_states", lambda m, w=w: latest.put(w, m), 10
        )
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    of = latest.of
    latest.until(
        lambda: len(of) == worlds and all(p.get_subscription_count() for p in pubs.values()),
        60,
    )
    out(ready_s=time.perf_counter() - t_made)
    for line in sys.stdin:
        w, sign, delay = int(line.split()[0]), float(line.split()[1]), float(line.split()[2])
        latest.until(lambda w=w: abs(of[w][2]) < REST, 5)
        seen = of[w][0]
        latest.until(lambda w=w, seen=seen: of[w][0] > seen, 1)
        before = of[w][1]
        time.sleep(delay)
        msg = JointState()
        msg.name, msg.position = ["elbow_joint"], [before + 0.05 * sign]
        t0 = time.perf_counter()
        pubs[w].publish(msg)
        moved = latest.until(
            lambda w=w, t0=t0, before=before, sign=sign: (
                of[w][0] > t0 and sign * (of[w][1] - before) >= 1e-4
            ),
            5,
        )
        out(ms=(of[w][0] - t0) * 1e3 if moved else None)
    executor.shutdown()


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
