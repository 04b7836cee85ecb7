"""Ray across two hosts, made here: two network namespaces joined by a veth pair.

`TwoHosts` makes the hosts ("head" 10.219.N.1 and "worker" 10.219.N.2, nothing else on their
network), starts a Ray head on one and a Ray node on the other (`ray start`, each bound to its
veth address, token authentication on, a temp dir of its own), and runs `armfleet serve --ray
HEAD:6379` on the head host. Its HTTP API is reached from a thread that has entered the head's
namespace (`setns`), so nothing listens outside the namespaces. `kill_host` SIGKILLs every
process of a host, as losing the machine would. Every process it stops is one it started
(found by namespace, never by name). Needs root, `ip` and `ss` (iproute2).

`measure()` (section 22 of `armfleet bench`, or `python -m bench.ray_hosts`): how long until the
worlds of a lost host step again, rebuilt on the head from their last state copy, and how the
other worlds stepped meanwhile. tests/test_ray_hosts.py checks the behaviour on the same set-up.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import ctypes
import json
import os
import random
import re
import secrets
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from bench.registry import Context, Result, section

ROOT = Path(__file__).resolve().parent.parent
RAY_PORT = 6379
HTTP_PORT = 8000  # a namespace of our own: every port is free
_CLONE_NEWNET = 0x40000000
# Ray notices a silent node after 3 missed checks 0.5 s apart (defaults: 5 × 3 s); set on every
# node, the serving process included.
FAST_HEALTH = {
    "RAY_health_check_period_ms": "500",
    "RAY_health_check_timeout_ms": "1000",
    "RAY_health_check_failure_threshold": "3",
}


def why_not() -> str | None:
    """Why two hosts cannot be made here (None: they can)."""
    if os.geteuid() != 0:
        return "two hosts need root to make network namespaces"
    if not (shutil.which("ip") and shutil.which("ss")):
        return "two hosts need `ip` and `ss` (iproute2)"
    if not shutil.which(
        "ray", path=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")])
    ):
        return "Ray is not installed (pip install -e '.[ray]')"
    return None


class NsHttp:
    """httpx calls made from one thread that lives in a network namespace (its own sockets)."""

    def __init__(self, ns: str, base_url: str) -> None:
        def enter() -> None:
            fd = os.open(f"/var/run/netns/{ns}", os.O_RDONLY)
            try:
                if ctypes.CDLL(None, use_errno=True).setns(fd, _CLONE_NEWNET) != 0:
                    raise OSError(ctypes.get_errno(), f"setns into {ns}")
            finally:
                os.close(fd)

        self._pool = concurrent.futures.ThreadPoolExecutor(1, initializer=enter)
        self._client = self._pool.submit(httpx.Client, base_url=base_url, timeout=60).result()

    def get(self, path: str) -> httpx.Response:
        return self._pool.submit(self._client.get, path).result()

    def post(self, path: str, body: Any) -> httpx.Response:
        return self._pool.submit(self._client.post, path, json=body).result()

    def close(self) -> None:
        self._pool.submit(self._client.close).result()
        self._pool.shutdown()


class TwoHosts:
    """A head host and a worker host (network namespaces) joined by a veth pair."""

    def __init__(self) -> None:
        tag = f"{os.getpid() % 1000}{random.randrange(100)}"
        net = 16 + (os.getpid() + random.randrange(200)) % 200
        self.ns = {"head": f"af19-{tag}-h", "worker": f"af19-{tag}-w"}
        self.dev = {"head": f"af19{tag}h", "worker": f"af19{tag}w"}
        self.ip = {"head": f"10.219.{net}.1", "worker": f"10.219.{net}.2"}
        # Short paths: Ray's unix sockets live under its temp dir (108-byte limit).
        self.tmp = Path(tempfile.mkdtemp(prefix="af19ray"))
        # A driver that already joined a local Ray in this process (ray_actor.connect) sets
        # RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0, which makes `ray start` refuse to join a head.
        skip = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
        inherited = {k: v for k, v in os.environ.items() if k != skip}
        self.env = {
            **inherited,
            **FAST_HEALTH,
            "RAY_AUTH_MODE": "token",  # every node and the driver present the same token
            "RAY_AUTH_TOKEN": secrets.token_hex(32),
            "RAY_USAGE_STATS_ENABLED": "0",
            "PYTHONPATH": str(ROOT),
        }
        self.bin = Path(sys.executable).parent

    def up(self) -> None:
        for ns in self.ns.values():
            _ip("netns", "add", ns)
        h, w = self.ns["head"], self.ns["worker"]
        _ip("link", "add", self.dev["head"], "netns", h, "type", "veth",
            "peer", "name", self.dev["worker"], "netns", w)  # fmt: skip
        for host, ns in self.ns.items():
            _ip("-n", ns, "addr", "add", f"{self.ip[host]}/24", "dev", self.dev[host])
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", ns, "link", "set", self.dev[host], "up")

    def down(self) -> None:
        for host in self.ns:
            self.kill_host(host)
        for ns in self.ns.values():
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        shutil.rmtree(self.tmp, ignore_errors=True)

    def run(self, host: str, *cmd: str) -> list[str]:
        return ["ip", "netns", "exec", self.ns[host], *cmd]

    def start_ray(self) -> None:
        """The head (2 CPUs: room for a lost shard) and a worker node (1 CPU)."""
        common = ["--disable-usage-stats", "--object-store-memory", str(80 << 20)]
        head = self.ip["head"]
        self._ray("head", "--head", "--port", str(RAY_PORT), "--num-cpus", "2",
                  "--include-dashboard", "false", *common)  # fmt: skip
        self._ray("worker", "--address", f"{head}:{RAY_PORT}", "--num-cpus", "1", *common)

    def _ray(self, host: str, *args: str) -> None:
        cmd = self.run(host, str(self.bin / "ray"), "start", "--node-ip-address", self.ip[host],
                       "--temp-dir", str(self.tmp / host), *args)  # fmt: skip
        done = subprocess.run(cmd, env=self.env, capture_output=True, text=True, timeout=180)
        if done.returncode:
            raise RuntimeError(f"ray start on {host} failed: {done.stderr[-2000:]}")

    def serve(self, log: Path, *flags: str) -> subprocess.Popen[bytes]:
        """`armfleet serve --ray HEAD:6379 FLAGS` on the head host (its output into `log`)."""
        ray = f"{self.ip['head']}:{RAY_PORT}"
        cmd = self.run("head", sys.executable, "-m", "service.cli", "serve", "--ray", ray,
                       "--port", str(HTTP_PORT), *flags)  # fmt: skip
        with open(log, "wb") as out:
            return subprocess.Popen(
                cmd, env=self.env, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT
            )

    def http(self) -> NsHttp:
        return NsHttp(self.ns["head"], f"http://127.0.0.1:{HTTP_PORT}")

    def pids(self, host: str) -> list[int]:
        out = subprocess.run(["ip", "netns", "pids", self.ns[host]], capture_output=True, text=True)
        return [int(p) for p in out.stdout.split()]

    def kill_host(self, host: str) -> int:
        """SIGKILL every process in the host's namespace (all started here); how many."""
        pids = self.pids(host)
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, 9)
        return len(pids)

    def shard_actors(self, host: str) -> int:
        """Ray actor processes holding a shard on the host (their title is ray::ShardActor)."""
        count = 0
        for pid in self.pids(host):
            with contextlib.suppress(OSError):
                count += Path(f"/proc/{pid}/cmdline").read_bytes().startswith(b"ray::ShardActor")
        return count

    def listeners(self, host: str) -> list[dict[str, str]]:
        """TCP listening sockets in the host's namespace: address, port, process."""
        out = subprocess.run(self.run(host, "ss", "-ltnpH"), capture_output=True, text=True).stdout
        rows = []
        for line in out.splitlines():
            parts = line.split()
            address, _, port = parts[3].rpartition(":")
            proc = re.search(r'\(\("([^"]+)"', line)
            rows.append(
                {"address": address, "port": port, "process": proc.group(1) if proc else ""}
            )
        return rows


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


def serve_flags(hosts: TwoHosts, nworld: int) -> list[str]:
    """Two shards, paused (ticks only when asked), state copies every 0.5 s, nothing saved."""
    data = str(hosts.tmp / "data")
    return ["--engine", "warp", "--worlds", str(nworld), "--shards", "2", "--mode", "paused",
            "--ray-checkpoint-s", "0.5", "--no-save-on-exit", "--data-dir", data]  # fmt: skip


def wait_ready(http: NsHttp, proc: subprocess.Popen[bytes], log: Path, limit: float = 240) -> None:
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"serve exited {proc.returncode}: {log.read_text()[-3000:]}")
        try:
            if http.get("/readyz").status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    raise RuntimeError(f"serve not ready in {limit} s: {log.read_text()[-3000:]}")


def positions(http: NsHttp) -> list[list[float]]:
    states = http.get("/v1/worlds/state").raise_for_status().json()["worlds"]
    return [w["position"] for w in states]


def wave(tick: int, nworld: int, home: list[float]) -> list[list[float]]:
    """Targets that keep every world moving: a slow wave on the elbow, per world a phase."""
    import math

    return [
        [*home[:2], home[2] + 0.3 * math.sin(0.05 * tick + w), *home[3:]] for w in range(nworld)
    ]


def recover(
    hosts: TwoHosts,
    http: NsHttp,
    nworld: int,
    home: list[float],
    on_step: Any = None,
    limit: float = 120,
) -> dict[str, Any]:
    """Kill the worker host, then step one tick per call (new targets each, also given to
    `on_step(targets)`) until the worlds that froze move again. Returns the timings, which
    worlds froze, and whether the others moved at every tick meanwhile."""
    before = positions(http)
    tick0 = http.get("/v1/info").json()["tick"]
    t0 = time.monotonic()
    killed = hosts.kill_host("worker")
    calls: list[float] = []
    frozen: set[int] = set()
    others_moved = True
    back = False
    while time.monotonic() - t0 < limit and not back:
        tick = http.get("/v1/info").json()["tick"]
        targets = wave(tick, nworld, home)
        http.post("/v1/targets", {"worlds": list(range(nworld)), "position": targets})
        t1 = time.monotonic()
        http.post("/v1/sim/step", {"ticks": 1}).raise_for_status()
        calls.append(time.monotonic() - t1)
        if on_step is not None:
            on_step(targets)
        now = positions(http)
        still = {w for w in range(nworld) if now[w] == before[w]}
        if frozen:
            back = not (still & frozen)
            others_moved &= not (still - frozen)
        else:
            frozen = still
        before = now
    return {
        "killed_processes": killed,
        "recover_s": round(time.monotonic() - t0, 2),
        "recovered": back,
        "ticks_meanwhile": http.get("/v1/info").json()["tick"] - tick0,
        "slowest_step_call_s": round(max(calls), 3),
        "median_step_call_s": round(sorted(calls)[len(calls) // 2], 4),
        "frozen_worlds": sorted(frozen),
        "other_worlds_moved_every_tick": others_moved,
    }


def measure(nworld: int = 4, say: Any = print) -> dict[str, Any]:
    """The whole two-host run, once (about a minute on 2 cores)."""
    hosts = TwoHosts()
    log = hosts.tmp / "serve.log"
    out: dict[str, Any] = {"nworld": nworld}
    try:
        hosts.up()
        t0 = time.monotonic()
        hosts.start_ray()
        out["ray_start_s"] = round(time.monotonic() - t0, 1)
        t0 = time.monotonic()
        proc = hosts.serve(log, *serve_flags(hosts, nworld))
        http = hosts.http()
        wait_ready(http, proc, log)
        out["serve_ready_s"] = round(time.monotonic() - t0, 1)
        out["shards"] = {h: hosts.shard_actors(h) for h in hosts.ns}
        out["listeners"] = {h: hosts.listeners(h) for h in hosts.ns}
        home = http.get("/v1/info").json()["joints"]
        home = [j["home"] for j in home]
        for t in range(0, 60, 10):
            http.post(
                "/v1/targets", {"worlds": list(range(nworld)), "position": wave(t, nworld, home)}
            )
            http.post("/v1/sim/step", {"ticks": 10}).raise_for_status()
        time.sleep(1.0)  # a state copy of every shard (every 0.5 s) has arrived
        http.post("/v1/sim/step", {"ticks": 1}).raise_for_status()
        say(
            f"two hosts up: ray {out['ray_start_s']} s, serve {out['serve_ready_s']} s, "
            f"shards {out['shards']}"
        )
        out["loss"] = recover(hosts, http, nworld, home)
        out["shards_after"] = {h: hosts.shard_actors(h) for h in ("head",)}
        found = re.search(r"resume from tick (\d+) \(now (\d+)\)", log.read_text())
        out["resumed_from_tick"] = int(found.group(1)) if found else None
        http.close()
        return out
    finally:
        hosts.down()


@section(22, "ray_hosts", default_on=())
def ray_hosts(ctx: Context) -> Result:
    """Ray across two hosts (network namespaces): a lost host's worlds back"""
    if why := why_not():
        return Result([], data={"skipped": why}, notes=[f"skipped: {why}"])
    payload = measure(say=ctx.say)
    loss = payload["loss"]
    row = {
        "worlds": payload["nworld"],
        "shards head/worker": f"{payload['shards']['head']}/{payload['shards']['worker']}",
        "ray start s": payload["ray_start_s"],
        "serve ready s": payload["serve_ready_s"],
        "recover s": loss["recover_s"],
        "ticks meanwhile": loss["ticks_meanwhile"],
        "slowest step call s": loss["slowest_step_call_s"],
    }
    notes = [
        "recover: SIGKILL of every process on the worker host → its worlds step again, "
        f"rebuilt on the head from the copy of tick {payload['resumed_from_tick']}",
    ]
    return Result([row], data=payload, notes=notes)


if __name__ == "__main__":
    print(json.dumps(measure(), indent=1))
