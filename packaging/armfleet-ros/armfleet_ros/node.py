"""`armfleet_node`: armfleet's worlds on the ROS 2 graph, as a node of the user's own ROS.

    ros2 run armfleet_ros armfleet_node --ros-args -p url:=http://127.0.0.1:8000 -p worlds:=0-7

It reaches armfleet by URL (HTTP and WebSocket, with armfleet's client library), so armfleet may
run on another machine; everything ROS (middleware, QoS, graph, type hashes, services, actions)
is the installation's own. Parameters: `url`, `worlds` (worlds with `/world_N/...`; world 0 is
also at the root, the seed's names), `rate` (Hz of `/joint_states`, `/clock`, `/tf`),
`play_mode` (what simulation_interfaces' PLAYING means: realtime or fast), `command_rate`
(armfleet's `--command-rate`, the budget of each of the node's command lanes: lanes.py),
`cameras` and `camera_rate` (camera images per namespace: cameras.py). The root namespace
is made at start, a `/world_N`'s endpoints at their first use on the graph (namespaces.py).
Written for Python 3.10 and rclpy 3.3 (Humble) on: no newer API is used.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from armfleet_ros import auth
from armfleet_ros.actions import TRAJECTORY_ACTIONS, GripperAction, TrajectoryAction
from armfleet_ros.cameras import camera_topics
from armfleet_ros.frames import TfTree
from armfleet_ros.link import FleetLink
from armfleet_ros.namespaces import TOPICS, Namespaces
from armfleet_ros.params import param
from armfleet_ros.parts import QUIET_PUB, Parts
from armfleet_ros.world import WorldTopics
from clients import ArmfleetClient, ros_rules
from clients.calls import Call
from clients.errors import ArmfleetError

NODE_NAME = "armfleet"
# A thread woken by its socket or by DDS (a command's callback, a lane's ack and owed frame)
# waits for the interpreter while another thread runs Python, up to the switch interval (5 ms
# by default: longer than most of the node's bursts, an executor's walk of its entities, a
# frame's publishing, the report's HTTP call, so such a burst ran to its end first). Traced
# rounds showed a command's callback -> written at p99 6.9-7.6 ms (0.2 ms median) now and then.
SWITCH_INTERVAL_S = 0.001
SIM = "simulation_interfaces"  # the group of a world's simulation_interfaces services


def _urdf(body: dict) -> str:
    return body["urdf"]


def parse_worlds(spec: str, nworld: int) -> list[int]:
    """'0-7,9' → [0, ..., 7, 9] (each < nworld); '' → []."""
    out: list[int] = []
    for part in filter(None, (p.strip() for p in spec.split(","))):
        lo, _, hi = part.partition("-")
        first, last = int(lo), int(hi or lo)
        if not 0 <= first <= last < nworld:
            raise ValueError(f"worlds: {part!r} is outside 0..{nworld - 1}")
        out.extend(range(first, last + 1))
    return sorted(set(out))


class ArmfleetNode:
    """The node, its link to armfleet and every world's topics and actions."""

    def __init__(self, node: Node) -> None:
        self.node = node  # parameters, /clock and the first slice's topics (parts.py)
        # Start's lines go to Python's logging, as the link's do: rclpy's logger reads the
        # caller's source on its first call (inspect: about a second on a busy 2-core box)
        log = logging.getLogger("armfleet_ros")
        self.url = str(param(node, "url", "http://127.0.0.1:8000"))
        spec = str(param(node, "worlds", ""))  # `worlds:=3` arrives as an integer
        self.rate = float(param(node, "rate", 60.0))  # `rate:=100` too
        self.http = ArmfleetClient(self.url, timeout=10.0, token=auth.token())
        self._wait_for_armfleet(log)
        info = self.http.info()
        self.joints = info.names
        self.tick_dt = 1.0 / info.control_hz
        self.worlds = parse_worlds(spec, info.nworld)
        with ThreadPoolExecutor(3, thread_name_prefix="armfleet-start") as pool:
            # the reads the root namespace needs, in flight together and beside the import
            urdf = pool.submit(self.http.call, Call("GET", "/v1/ros/robot_description", _urdf))
            frames = pool.submit(self.http.call, Call("GET", "/v1/ros/frames", lambda d: d))
            free = pool.submit(self.http.entities, 0)  # every world has the same scene
            self._sim = self._simulation_interfaces(log)
            self.urdf, self.frames = urdf.result(), frames.result()
            self.free_bodies = [e["name"] for e in free.result()["entities"]]
        self.tree = TfTree(self.frames)
        # refusals are warnings of the ROS node (on /rosout too)
        self.bad = ros_rules.RefusalCounter("armfleet_ros", node.get_logger().warning)
        self.accepted = 0
        self._publish_lock = threading.Lock()
        self._clock_tick = -1
        self._world_tick: dict[int, int] = {}
        self._layouts: dict[bytes, dict[int, int]] = {}  # _rows_of
        self._last_generation = 0
        self._reported: dict = {}
        self._reported_at = 0.0
        self.clock = node.create_publisher(Clock, "/clock", 10, **QUIET_PUB)
        self.parts = Parts(NODE_NAME, node)
        # what the open namespaces have made (namespaces.py); lists replaced, never changed
        self.spaces: list[WorldTopics] = []
        self.servers: list[Any] = []  # action servers and WorldSim services
        self._part_of: dict[str, Any] = {}  # a namespace's groups share its slice
        names = [c.strip() for c in str(param(node, "cameras", "")).split(",") if c.strip()]
        self.cameras = camera_topics(self, names, float(param(node, "camera_rate", 10.0)))
        served = {"": 0} | {f"/world_{w}": w for w in self.worlds}
        groups = {a: (a,) for a in (*TRAJECTORY_ACTIONS, ros_rules.GRIPPER_ACTION)}
        if self._sim is not None:
            groups[SIM] = self._sim.WORLD_SERVICES
        self.namespaces = Namespaces(node, served, groups, self._make)
        self.namespaces.open_all("")  # the root: the seed's names; the others at first use
        if self._sim is not None:
            self.sim = self._sim.GlobalSim(self, self.parts.first)
        worlds = sorted(set(served.values()))
        command_rate = float(param(node, "command_rate", 200.0))
        self.link = FleetLink(self.url, worlds, self.rate, self._publish, command_rate)
        self.link.start()
        self._stop = threading.Event()
        # not an executor timer: a wake-up of the topics executor walks all its entities
        threading.Thread(target=self._refresh_loop, name="armfleet-refresh", daemon=True).start()
        watch = threading.Thread(
            target=self.namespaces.watch, args=(self._stop,), name="armfleet-graph", daemon=True
        )
        watch.start()
        log.info(
            f"serving {len(worlds)} worlds of {self.url} ({len(served)} namespaces, "
            f"each made at its first use; {self.rate:g} Hz)"
        )

    def _simulation_interfaces(self, log: Any) -> Any:
        """The module of the standard simulator services, where the installation has the
        package (else None)."""
        try:
            from armfleet_ros import sim
        except ImportError as exc:
            log.warning(f"simulation_interfaces is not installed ({exc}): its services are off")
            return None
        return sim

    def _make(self, ns: str, world: int, group: str) -> None:
        """One group of a namespace's endpoints (namespaces.py), on the namespace's slice."""
        part = self._part_of.get(ns)
        if part is None:
            part = self._part_of[ns] = self.parts.place()
        if group == TOPICS:
            space = WorldTopics(self, world, ns, part)
            for camera in self.cameras:
                camera.add(part.topics, ns, world)
            self.spaces = [*self.spaces, space]
        elif group == SIM:
            self.servers = [*self.servers, self._sim.WorldSim(self, world, ns, part)]
        elif group == ros_rules.GRIPPER_ACTION:
            self.servers = [*self.servers, GripperAction(self, world, ns, part)]
        else:
            self.servers = [*self.servers, TrajectoryAction(self, world, ns, part, group)]

    def _wait_for_armfleet(self, log: Any) -> None:
        """Whichever starts first: wait (for ever) until armfleet answers /readyz."""
        if self.http.ready():
            return
        log.info(f"waiting for armfleet at {self.url}")
        while not self.http.ready():
            time.sleep(0.5)
        log.info(f"armfleet at {self.url} is ready")

    def _refresh_loop(self) -> None:
        while not self._stop.wait(0.5):
            try:
                self._refresh()
            except Exception as exc:  # never end the loop: it keeps state topics alive
                self.node.get_logger().warning(f"refresh: {exc}")

    def _refresh(self) -> None:
        for space in self.spaces:
            space.refresh()
        for camera in self.cameras:
            camera.refresh()
        self.link.watch_poses(sorted({s.world for s in self.spaces if s.listened_tf}))
        self._report()

    def _report(self) -> None:
        """The node's counters, shown by armfleet's `GET /v1/ros` (best effort): when they
        changed, else every 10 s."""
        body = {
            "name": f"/{NODE_NAME}",
            "connected": self.link.connected,
            "worlds": len(self.namespaces.served),
            "open": self.namespaces.open_namespaces(),
            "accepted": self.accepted,
            "merged": sum(lane.merged for lane in self.link.lanes),
            "rejected": self.bad.counts(),
            "images": {camera.name: camera.published for camera in self.cameras},
        }
        now = time.monotonic()
        if body == self._reported and now - self._reported_at < 10.0:
            return
        self._reported, self._reported_at = body, now
        with contextlib.suppress(ArmfleetError):
            self.http.call(Call("PUT", "/v1/ros/node", lambda d: d, json=body))

    def _publish(self, batch: Any) -> None:
        """A state frame arrived (a socket's thread: the state socket's or a command lane's; a
        catch-up: an executor thread): `/clock`, then each listened world the frame is news
        for, the worlds a command just went to first. Never back in time (the state socket
        and the command lanes deliver frames of the same ticks), unless armfleet restarted.
        The frame's worlds are claimed under one lock, and published each under its own
        (world.py): a lane's frame publishes the world it was owed for while the state
        socket's thread publishes the others, instead of waiting for all of them."""
        spaces = self.spaces  # the open namespaces': a frame's other worlds are not looked at
        with self._publish_lock:
            gen = self.link.generation
            if gen != self._last_generation:
                self._last_generation, self._clock_tick = gen, -1
                self._world_tick = {}
            tick = batch.tick
            sec, nanosec = ros_rules.stamp(tick * self.tick_dt)
            if tick > self._clock_tick:
                self._clock_tick = tick
                clock = Clock()
                clock.clock.sec, clock.clock.nanosec = sec, nanosec
                self.clock.publish(clock)
            row_of = self._rows_of(batch.worlds)
            rows = {}
            for space in spaces:
                w = space.world
                i = row_of.get(w)
                if i is not None and tick > self._world_tick.get(w, -1):
                    self._world_tick[w] = tick
                    rows[w] = i
        spaces = [s for s in spaces if s.world in rows]
        if not spaces:
            return
        owed = [s for s in spaces if s.owed_by(tick)]
        if owed:
            spaces = owed + [s for s in spaces if not s.owed_by(tick)]
        poses = self.link.poses
        for space in spaces:
            world_poses = None
            if space.listened_tf and poses is not None and space.world in poses.row:
                world_poses = poses.poses[poses.row[space.world]]
            space.publish(batch, rows[space.world], (gen, tick), sec, nanosec, world_poses)

    def _rows_of(self, worlds: Any) -> dict[int, int]:
        """world → row of a frame's world ids, kept per layout (the state socket's, each
        lane's, a catch-up's): a dict built for 256 worlds at every frame held the publish
        lock, which a lane's owed frame waits for, 0.3 ms a frame on the busy box."""
        key = worlds.tobytes()
        row_of = self._layouts.get(key)
        if row_of is None:
            if len(self._layouts) >= 64:  # a few layouts live at a time: never grows for ever
                self._layouts.clear()
            row_of = self._layouts[key] = {w: i for i, w in enumerate(worlds.tolist())}
        return row_of

    def catch_up(self) -> None:
        """Publish the states of now, read over HTTP: after a pause or steps through this node
        (armfleet's stream keeps its cadence, so a burst of stepped ticks ends between frames
        and, paused, no later frame comes)."""
        try:
            self._publish(self.http.states(self.link.worlds))
        except ArmfleetError as exc:
            self.node.get_logger().warning(f"states after a step: {exc}")

    def close(self) -> None:
        self._stop.set()
        for camera in self.cameras:
            camera.stop()
        self.link.stop()
        self.http.close()


def main(args: list | None = None) -> None:
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    logging.basicConfig(level=logging.INFO, format="[armfleet_ros] %(message)s")
    logging.getLogger("httpx").setLevel(logging.WARNING)
    rclpy.init(args=args)
    node = Node(NODE_NAME)
    try:
        fleet = ArmfleetNode(node)
    except (ValueError, ArmfleetError) as exc:
        node.get_logger().error(str(exc))
        node.destroy_node()
        rclpy.shutdown()
        sys.exit(2)
    executor = fleet.parts.first.topic_executor  # the other executors: threads (parts.py)
    try:
        # Timed turns, not spin(): now and then SIGINT shut the context down without waking
        # an idle spin() (armfleet gone, nothing to call back), and the node never exited.
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.5)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        fleet.close()
        fleet.parts.close()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    main()
