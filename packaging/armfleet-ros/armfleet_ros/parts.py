"""The node's namespaces in slices, each slice on ROS nodes and executors of its own.

rclpy walks every entity of an executor's nodes on each wake-up (Python work per entity), so
one node holding 256 worlds' endpoints (about 1,000 subscriptions and 7,000 service and action
endpoints) answers a command only after walking all of them: hundreds of milliseconds. So
every 16 namespaces get their own pair of nodes: one for the topics, spun by a single thread,
and one for the actions and services, whose callbacks block, spun by a small pool. Slice 0's
topics node is `armfleet` itself (parameters, `/clock`); the others are `armfleet_<k>` and
`armfleet_actions[_<k>]`.
"""

from __future__ import annotations

from typing import Any

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node

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


def slices(spaces: list[tuple[str, int]], name: str, main: Node) -> list[tuple[Part, list]]:
    """(part, its namespaces) for every SLICE namespaces; the first part's topics are `main`."""
    out = []
    for k in range(0, len(spaces), SLICE):
        part = Part(k // SLICE, name, main if k == 0 else None)
        out.append((part, spaces[k : k + SLICE]))
    return out
