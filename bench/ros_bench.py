"""ROS section: JointState round trips over DDS and rosbridge, and a DDS command flood.

* Round trip, realtime mode, states at 60 Hz: a client publishes a JointState command that moves
  `wrist_3_joint` by ±0.1 rad (alternating, so the arm stays in range) and times, from the
  publish, the first `/joint_states` message where the joint has started to move in the commanded
  direction (``responds``: >= 1e-5 rad, the first state stepped with the new target; the hold
  error at rest is < 1e-12 rad) and where it has moved >= 0.01 rad (``moved``). The next command
  goes out after a random 0-17 ms pause so that the samples spread over the tick phase.
  Over DDS the client is a Cyclone DDS participant of its own (this process), or a Fast DDS
  node set up as Humble's rmw_fastrtps_cpp (bench/dds_peers.py); over rosbridge it is a
  WebSocket client at `/rosbridge`.
* Time to first match of a fresh Fast DDS or Cyclone node started after armfleet
  (bench/dds_peers.py).
* Flood: 1000 JointState commands per second, spread over `/world_0..15/joint_commands`, for
  `duration` seconds at 16 worlds; the loop's real-time factor meanwhile and how many commands
  the service accepted (`GET /v1/ros`).

Everything runs on loopback, in a DDS domain of its own. Standalone:
``python -m bench.ros_bench [--quick]`` or ``armfleet bench --section 8``.
"""

from __future__ import annotations

import json
import random
import time
from collections.abc import Callable
from typing import Any

import httpx
import orjson

from bench import common, dds_peers
from bench.registry import Context, Result, section

SECTION = "ros"
JOINT = "wrist_3_joint"
JOINT_INDEX = 5
DELTA = 0.1
RESPONDS = 1e-5
MOVED = 0.01
TIMEOUT = 5.0


WORLDS = 16
FLOOD_RATE = 1000.0


# -- DDS client ------------------------------------------------------------------------------


class DdsClient:
    """A participant of its own on the loopback configuration, in the bench process."""

    def __init__(self, domain: int, worlds: int) -> None:
        from cyclonedds.domain import Domain, DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from service.surfaces.ros import msgs
        from service.surfaces.ros.dds import LOOPBACK_CONFIG, _qos

        self.msgs = msgs
        self.domain = Domain(domain, LOOPBACK_CONFIG)
        self.dp = DomainParticipant(domain)
        js = msgs.JointState
        self.command = DataWriter(self.dp, Topic(self.dp, "rt/joint_commands", js), qos=_qos(10))
        self.world_commands = [
            DataWriter(self.dp, Topic(self.dp, f"rt/world_{w}/joint_commands", js), qos=_qos(100))
            for w in range(worlds)
        ]
        self.states = DataReader(self.dp, Topic(self.dp, "rt/joint_states", js), qos=_qos(10))
        deadline = time.monotonic() + 20
        writers = [self.command, *self.world_commands]
        while not (
            all(w.get_publication_matched_status().current_count for w in writers)
            and self.states.get_subscription_matched_status().current_count
        ):
            if time.monotonic() > deadline:
                raise RuntimeError("armfleet's DDS endpoints were not discovered in 20 s")
            time.sleep(0.05)

    def send(self, writer: Any, name: list[str], position: list[float]) -> None:
        writer.write(self.msgs.JointState(name=name, position=position))

    def next_state(self, timeout: float) -> tuple[float, list[float]] | None:
        """(receive time, position) of the next /joint_states sample, polling every 0.2 ms."""
        deadline = time.perf_counter() + timeout
        while time.perf_counter() < deadline:
            for sample in self.states.take(N=16):
                if isinstance(sample, self.msgs.JointState):
                    return time.perf_counter(), list(sample.position)
            time.sleep(0.0002)
        return None

    def close(self) -> None:
        for entity in (*self.world_commands, self.command, self.states, self.dp, self.domain):
            entity.__del__()


def _settle(
    next_state: Callable[[float], tuple[float, list[float]] | None], target: float
) -> float:
    """Read states until the joint is within 0.01 rad of `target` (2 s at most); its position."""
    position = float("nan")
    deadline = time.perf_counter() + 2.0
    while time.perf_counter() < deadline:
        s = next_state(0.1)
        if s is not None:
            position = s[1][JOINT_INDEX]
            if abs(position - target) < 0.01:
                break
    return position


def _round_trips(
    send: Callable[[float], None],
    next_state: Callable[[float], tuple[float, list[float]] | None],
    n: int,
) -> dict[str, Any]:
    """The shared measurement loop: `send(target)` publishes, `next_state` yields states."""
    rng = random.Random(1)
    out: dict[str, list[float]] = {"responds": [], "moved": []}
    timeouts = 0
    target = 0.0
    send(target)  # start from rest at a known target
    position = _settle(next_state, target)
    sign = 1.0
    for _ in range(n):
        time.sleep(rng.uniform(0, 1 / 60))
        while (s := next_state(0.0005)) is not None:  # the newest state before the send
            position = s[1][JOINT_INDEX]
        target = round(target + sign * DELTA, 9)
        direction, sign = sign, -sign
        t_send = time.perf_counter()
        send(target)
        t_responds = None
        while True:
            s = next_state(0.1)
            if time.perf_counter() - t_send > TIMEOUT:
                timeouts += 1
                break
            if s is None:
                continue
            moved = (s[1][JOINT_INDEX] - position) * direction
            if t_responds is None and moved >= RESPONDS:
                t_responds = s[0]
                out["responds"].append(t_responds - t_send)
            if moved >= MOVED:
                out["moved"].append(s[0] - t_send)
                break
        position = _settle(next_state, target)
    return {
        "commands": n,
        "timeouts": timeouts,
        "responds": common.summary_ms(out["responds"]),
        "moved": common.summary_ms(out["moved"]),
    }


def dds_round_trip(client: DdsClient, n: int) -> dict[str, Any]:
    return _round_trips(
        lambda target: client.send(client.command, [JOINT], [target]), client.next_state, n
    )


def rosbridge_round_trip(ws_url: str, n: int) -> dict[str, Any]:
    """The same loop over a rosbridge WebSocket at /rosbridge (JSON text frames)."""
    from websockets.sync.client import connect

    with connect(ws_url + "/rosbridge", compression=None, max_size=None) as ws:
        ws.send(json.dumps({"op": "subscribe", "id": "s", "topic": "/joint_states"}))
        ws.send(
            json.dumps(
                {"op": "advertise", "topic": "/joint_commands", "type": "sensor_msgs/JointState"}
            )
        )

        def send(target: float) -> None:
            msg = {"name": [JOINT], "position": [target]}
            ws.send(json.dumps({"op": "publish", "topic": "/joint_commands", "msg": msg}))

        def next_state(timeout: float) -> tuple[float, list[float]] | None:
            try:
                frame = orjson.loads(ws.recv(timeout=timeout))
            except TimeoutError:
                return None
            if frame.get("op") != "publish":
                raise RuntimeError(f"unexpected frame {frame}")
            return time.perf_counter(), frame["msg"]["position"]

        return _round_trips(send, next_state, n)


def flood(server: common.Served, client: DdsClient, rate: float, seconds: float) -> dict[str, Any]:
    """`rate` commands/s over the world topics for `seconds`; RTF and acceptance meanwhile."""
    names = ["finger_joint"]
    before = httpx.get(f"{server.url}/v1/ros").json()["dds"]
    t_info0, info0 = server.get_info()
    sent = 0
    period = 1.0 / rate
    t0 = time.perf_counter()
    nworld = len(client.world_commands)
    while (now := time.perf_counter()) - t0 < seconds:
        due = int((now - t0) * rate) + 1
        while sent < due:
            w = sent % nworld
            client.send(client.world_commands[w], names, [0.7 * ((sent // nworld) % 2)])
            sent += 1
        time.sleep(period / 2)
    wall = time.perf_counter() - t0
    t_info1, info1 = server.get_info()
    time.sleep(0.5)  # the last commands in flight
    after = httpx.get(f"{server.url}/v1/ros").json()["dds"]
    return {
        "worlds": nworld,
        "rate_wanted": rate,
        "sent": sent,
        "sent_per_s": sent / wall,
        "accepted": after["commands_accepted"] - before["commands_accepted"],
        "rejected": sum(after["rejected"].values()) - sum(before["rejected"].values()),
        "realtime_factor": common.rtf(
            info1["tick"] - info0["tick"], info1["control_hz"], t_info1 - t_info0
        ),
        "seconds": wall,
    }


@section(
    8,
    "ros",
    "ROS 2 over DDS and rosbridge: JointState round trip (Cyclone, Fast DDS, rosbridge), "
    "time to first match, 1000 commands/s",
)
def ros(ctx: Context) -> Result:
    """One realtime server with `--ros2` on every world; round trips, then the flood."""
    worlds = (ctx.worlds or [WORLDS])[0]
    round_trips = ctx.pick(200, 50)
    flood_s = ctx.pick(20.0, 5.0)
    domain = random.SystemRandom().randrange(1, 233)  # a DDS domain of its own
    env = {
        "ROS_DOMAIN_ID": str(domain),
        "ARMFLEET_ROS2": "true",
        "ARMFLEET_ROS2_WORLDS": f"0-{worlds - 1}",
        "ARMFLEET_ROS2_RATE": "60",
    }
    data: dict[str, Any] = {"worlds": worlds, "state_rate_hz": 60, "errors": {}}
    with ctx.serve(worlds, "realtime", env) as server:
        client = DdsClient(domain, worlds)
        try:
            data["rtf_idle"] = common.rtf_between(server.get_info(), _after(server, 3.0))
            for key, measure in (
                ("dds", lambda: dds_round_trip(client, round_trips)),
                ("rosbridge", lambda: rosbridge_round_trip(server.ws_url, round_trips)),
                (
                    "fastdds",
                    lambda: dds_peers.fastdds_round_trip(domain, round_trips, _round_trips, JOINT),
                ),
                ("first_match", lambda: first_matches(domain, ctx.pick(30, 10))),
                ("flood", lambda: flood(server, client, FLOOD_RATE, flood_s)),
            ):
                try:
                    data[key] = measure()
                except Exception as exc:
                    data["errors"][key] = f"{type(exc).__name__}: {exc}"
                    ctx.say(f"  {key} FAILED: {data['errors'][key]}")
                else:
                    ctx.say(f"  {key}: done")
        finally:
            client.close()
    rows: list[dict[str, Any]] = []
    for key, label in (
        ("dds", "DDS (Cyclone)"),
        ("fastdds", "DDS (Fast DDS node)"),
        ("rosbridge", "rosbridge"),
    ):
        r = data.get(key)
        for what in ("responds", "moved") if r else ():
            rows.append(
                {
                    "measure": f"{label} round trip, {what}",
                    "p50 ms": r[what]["p50_ms"],
                    "p99 ms": r[what]["p99_ms"],
                    "n": r[what]["n"],
                    "notes": f"timeouts {r['timeouts']}",
                }
            )
    for kind, label in FIRST_MATCH.items():
        m = data.get("first_match", {}).get(kind)
        if m:
            rows.append(
                {
                    "measure": f"time to first match: {label}",
                    "p50 ms": m["p50_ms"],
                    "p99 ms": m["p99_ms"],
                    "n": m["n"],
                    "notes": "fresh node started after armfleet",
                }
            )
    f = data.get("flood")
    if f:
        rows.append(
            {
                "measure": f"DDS {f['sent_per_s']:.0f} commands/s over {f['worlds']} worlds",
                "p50 ms": "",
                "p99 ms": "",
                "n": f["sent"],
                "notes": f"RTF {f['realtime_factor']:.3f} (idle {data['rtf_idle']:.3f}), "
                f"accepted {f['accepted']}, rejected {f['rejected']}",
            }
        )
    notes = [
        f"{worlds} worlds, realtime, states at 60 Hz; responds = first state moved >= "
        f"{RESPONDS:g} rad toward the command, moved = >= {MOVED:g} rad"
    ]
    return Result(rows, data, notes)


FIRST_MATCH = {
    "fastdds": "Fast DDS node (Humble rmw_fastrtps_cpp, ROS_LOCALHOST_ONLY=1)",
    "cyclone_unicast": "Cyclone node (unicast-only discovery on 127.0.0.1)",
    "cyclone_loopback": "Cyclone node (armfleet's loopback configuration)",
}


def first_matches(domain: int, n: int) -> dict[str, Any]:
    """Time to first match of fresh nodes of each kind (bench/dds_peers.py says how)."""
    from service.surfaces.ros.discovery import LOOPBACK_CONFIG

    return {
        "fastdds": common.summary_ms(dds_peers.fastdds_first_matches(domain, n)),
        "cyclone_unicast": common.summary_ms(
            dds_peers.cyclone_first_matches(domain, n, dds_peers.UNICAST_ONLY)
        ),
        "cyclone_loopback": common.summary_ms(
            dds_peers.cyclone_first_matches(domain, n, LOOPBACK_CONFIG)
        ),
    }


def _after(server: common.Served, seconds: float) -> tuple[float, dict[str, Any]]:
    time.sleep(seconds)
    return server.get_info()


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
