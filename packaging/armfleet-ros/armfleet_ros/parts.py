"""The node's open namespaces in slices, each slice on ROS nodes and executors of its own.

rclpy walks every entity of an executor's nodes on each wake-up (Python work per entity), so
one node holding 256 worlds' endpoints (about 1,000 subscriptions and 7,000 service and action
endpoints) answers a command only after walking all of them: hundreds of milliseconds. So
every 16 namespaces opened (namespaces.py: in the order they are first used) get their own pair
of nodes: one for the topics, spun by a single thread, and one for the actions and services,
whose callbacks block, spun by a small pool. A slice is made, and its threads started, when its
first namespace opens. Slice 0's topics node is `armfleet` itself (parameters, `/clock`; `main`
spins its executor); the others are `armfleet_<k>` and `armfleet_actions[_<k>]`.

A topic's publisher or subscription is made without rclpy's default event handlers (`QUIET_PUB`,
`QUIET_SUB`): each is a waitable of the node (two per endpoint on Jazzy: incompatible QoS and
incompatible type) that the executor walks on every wake-up, in Python. A slice's 16 namespaces
made about 200 of them, and its executor spent 3.5 ms of CPU per command message, 1.7 without
(one subscription of 64 taking 300 messages, 2-core Xeon). Their only work is a log line on this
side of a mismatch, which the other side's defaults log as well (rclpy and rclcpp warn on an
incompatible QoS offered or requested by the endpoints they match).
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node

try:  # Iron and later
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
except ImportError:  # Humble
    from rclpy.qos_event import PublisherEventCallbacks, SubscriptionEventCallbacks

# create_publisher / create_subscription keywords: no default event handlers (docstring)
QUIET_PUB = {"event_callbacks": PublisherEventCallbacks(use_default_callbacks=False)}
QUIET_SUB = {"event_callbacks": SubscriptionEventCallbacks(use_default_callbacks=False)}

SLICE = 16  # namespaces per slice
POOL_THREADS = 8  # running goals and service calls of one slice at once


class Part:
    """One slice: its topics node and executor, its servers node and pool."""

    def __init__(self, index: int, name: str, topics: Node | None = None) -> None:
        suffix = "" if index == 0 else f"_{index}"
        self.topics = topics or Node(f"{name}{suffix}")
        self.servers = Node(f"{name}_actions{suffix}")
        self.group = ReentrantCallbackGroup()
        self.topic_executor = SingleThreadedExecutor()
        self.topic_executor.add_node(self.topics)
        self.pool = MultiThreadedExecutor(num_threads=POOL_THREADS)
        self.pool.add_node(self.servers)

    def executors(self) -> list[Any]:
        return [self.topic_executor, self.pool]

    def close(self) -> None:
        for ex in self.executors():
            ex.shutdown()
        for n in (self.servers, self.topics):
            n.destroy_node()


class Parts:
    """The slices so far; `place` gives each namespace opened its slice."""

    def __init__(self, name: str, main: Node) -> None:
        self.name, self.main = name, main
        self.all: list[Part] = []
        self._placed = 0
        self._lock = threading.Lock()

    def place(self) -> Part:
        """The slice of the next namespace opened: a new one (spinning) every SLICE."""
        with self._lock:
            if self._placed % SLICE == 0:
                index = len(self.all)
                part = Part(index, self.name, self.main if index == 0 else None)
                # slice 0's topics executor is spun by `main` (the process's main thread)
                for ex in part.executors()[1 if index == 0 else 0 :]:
                    threading.Thread(
                        target=_spin, args=(ex,), name="armfleet-executor", daemon=True
                    ).start()
                self.all = [*self.all, part]
            self._placed += 1
            return self.all[-1]

    @property
    def first(self) -> Part:
        return self.all[0]

    def close(self) -> None:
        for part in self.all:
            part.close()


def _spin(executor: Any) -> None:
    with contextlib.suppress(Exception):  # ends with the context at shutdown
        executor.spin()
