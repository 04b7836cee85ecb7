"""When a namespace's endpoints are made: the root's at start, a `/world_N`'s at first use.

A namespace's topics, services and actions are about 40 DDS endpoints, and every endpoint costs
the process tens of kilobytes and its start a few milliseconds, more the more endpoints the
participant already has. Made at start for 256 worlds that was 30 s and 700 MB, for worlds and
interfaces nobody may ever use. So the root namespace (world 0, the seed's names) and the
global interfaces are made at start, and a `/world_N` namespace's endpoints come in groups, each
made as soon as anything on the ROS graph names one of its names:

- `topics`: the commands in, the states, `/tf`, `/tf_static`, `robot_description` and camera
  topics out (8 endpoints, and 2 a camera); any name of the namespace outside the groups below
  opens it (a publisher of `joint_commands`, a subscriber of `joint_states`, ...);
- each action server (8 endpoints): opened by its action client;
- the simulation_interfaces services of the world (10 endpoints): opened by a client of any.

The graph is read every WATCH_S seconds while any group is closed. A ROS user waits for a match
before sending (a subscription count, `wait_for_service`, `wait_for_server`), as with any DDS
reader not yet discovered; that wait now also covers the opening (WATCH_S at most, plus the
discovery of the new endpoints).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable
from typing import Any

log = logging.getLogger("armfleet_ros")

WATCH_S = 0.2
TOPICS = "topics"  # the group of every name no other group claims


class Namespaces:
    """The served namespaces ("" and `/world_N`), their open groups, and the graph watch."""

    def __init__(
        self,
        node: Any,
        served: dict[str, int],
        groups: dict[str, tuple[str, ...]],
        make: Callable[[str, int, str], None],
    ) -> None:
        """`groups`: group → the names (relative to the namespace) that open it, with every
        name below them (an action's `_action/...`); `make(ns, world, group)` makes them."""
        self.node = node
        self.served = dict(served)
        self.groups = {TOPICS: (), **groups}
        self._claims = [(name, g) for g, names in groups.items() for name in names]
        self.make = make
        self.opened: frozenset[tuple[str, str]] = frozenset()
        self._lock = threading.Lock()

    def open(self, ns: str, group: str) -> bool:
        """Make one group of `ns` unless it exists; whether it was made now."""
        with self._lock:
            if (ns, group) in self.opened or ns not in self.served:
                return False
            # marked open first: a group that failed halfway is not made twice
            self.opened = self.opened | {(ns, group)}
            self.make(ns, self.served[ns], group)
            return True

    def open_all(self, ns: str) -> None:
        for group in self.groups:
            self.open(ns, group)

    def group_of(self, rest: str) -> str:
        """The group a name relative to its namespace ('a/b', no leading slash) belongs to."""
        for name, group in self._claims:
            if rest == name or rest.startswith(name + "/"):
                return group
        return TOPICS

    def wanted(self, names: Iterable[str]) -> list[tuple[str, str]]:
        """The closed groups of served namespaces that `names` (graph names) reach into."""
        out = []
        for name in names:
            _, first, rest = (name.split("/", 2) + ["", ""])[:3]
            ns = "/" + first
            if not rest or ns not in self.served:
                continue
            key = (ns, self.group_of(rest))
            if key not in self.opened and key not in out:
                out.append(key)
        return out

    def open_namespaces(self) -> int:
        """How many namespaces have some group open."""
        return len({ns for ns, _ in self.opened})

    def watch(self, stop: threading.Event) -> None:
        """Open each group the graph names, until all are open or `stop` is set."""
        total = len(self.served) * len(self.groups)
        while len(self.opened) < total and not stop.wait(WATCH_S):
            try:
                names = [n for n, _ in self.node.get_topic_names_and_types()]
                names += [n for n, _ in self.node.get_service_names_and_types()]
                for ns, group in self.wanted(names):
                    if self.open(ns, group):
                        log.info("opened %s %s (first use)", ns, group)
            except Exception:  # never end the watch: a closed group would stay closed
                log.exception("opening a namespace failed")
