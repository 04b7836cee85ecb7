"""RayBatch: the batch's shards on Ray actors, on one machine or many, behind the Batch protocol.

One machine's GPUs (or cores) are the ceiling of WorldBatch and ShardedBatch. Here every shard is
a Ray actor holding a WorldBatch of its block of worlds: one per GPU on CUDA, else one per CPU core
(warp's CPU kernels run on one core). The API process keeps the loop, the target table and the
lockstep tick: each tick every shard gets its staged commands with the step (all `step.remote`
fired before any result is awaited), then the faulted worlds are gathered: bit-identical to one
WorldBatch of the same worlds (tests/test_ray_shards.py).

A shard whose actor dies (node lost, process killed) is noticed by the next call that reaches it
(`RayActorError`), and a new actor is started at once; the others keep stepping, the lost worlds
show their last state until it is ready. Every `checkpoint_s` (10 s) each shard's `BatchState` is
copied here; the new actor resumes from the last copy with the targets (and model values)
commanded since; without one, its worlds come back at `home` and `step` returns them as faulted,
as a NaN world comes back, so the loop and its clients treat them alike.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import time
from typing import Any

import numpy as np
import ray
from ray.exceptions import RayActorError

from mjcf import SCENE_XML
from service.core.errors import Unavailable
from service.core.sim.batch import Batch, Restorable, StateWrite
from service.core.sim.physics import configure, warp_solver
from service.core.sim.robot import load_robot
from service.core.sim.types import BatchState, Snapshot
from service.engines.mirror import HostMirror
from service.engines.ray_actor import NEVER, RemoteShard, Shard, connect, ray_auto_shards
from service.engines.sharding import (
    NOTHING,
    ShardPlan,
    StagedCommands,
    join_states,
    slice_state,
    stage_model,
    with_model,
)
from service.engines.warp_snapshot import SnapshotArrays, snapshot_from

log = logging.getLogger("armfleet.ray")

# How often each shard's full state is copied into the API process, so that a lost shard comes
# back where it was at most this long ago instead of at home (one state copy per shard each time).
CHECKPOINT_S = 10.0
# A shard whose new actor fails this many times in a row is left frozen (logged), not retried.
MAX_REBUILD_ATTEMPTS = 3


class RayBatch(HostMirror, Batch, Restorable):
    """N worlds as k contiguous shards, each a Ray actor holding a WorldBatch.

    Implements the Batch protocol (service/core/sim/batch.py). `address` is as in `connect`;
    None uses the Ray connection this process already has, or starts a local instance.
    """

    def __init__(
        self,
        nworld: int,
        shards: int = 0,
        *,
        address: str | None = None,
        device: str = "cpu",
        checkpoint_s: float = CHECKPOINT_S,
        **kwargs: Any,
    ) -> None:
        connect(address or "local")
        self.gpu = device.startswith("cuda")
        shards = shards or ray_auto_shards(nworld, device)
        self._plan = ShardPlan(nworld, shards)
        # On a GPU actor Ray exposes only its own GPU (CUDA_VISIBLE_DEVICES), so it is "cuda".
        self._kwargs = {"device": "cuda" if self.gpu else device, **kwargs}
        # SPREAD: shards on different nodes where there are several (a lost node costs fewest)
        self._options: dict[str, Any] = {"num_cpus": 1, "max_restarts": 0}
        self._options |= {"scheduling_strategy": "SPREAD", **({"num_gpus": 1} if self.gpu else {})}
        self._shards = [Shard(actor=self._spawn(i)) for i in range(shards)]
        try:
            infos = ray.get([s.actor.info.remote() for s in self._shards])
        except RayActorError as exc:
            self.close()
            raise RuntimeError(f"a Ray shard failed to start: {exc}") from exc
        info = infos[0]
        self.nworld = nworld
        self.shards = shards
        self.spec = info["spec"]
        self.control_hz, self.tick_dt = info["control_hz"], info["tick_dt"]
        self.substeps, self.physics_dt = info["substeps"], info["physics_dt"]
        # The model as the actors step it, for viewers (GET /v1/scene); nothing steps it here.
        self.robot = load_robot(kwargs.get("model_path", SCENE_XML))
        configure(self.robot.mjm, self.physics_dt, warp_solver(self.gpu))
        self.device_name = f"ray: {shards} × {info['device_name']}"
        self.nodes = len({i["node"] for i in infos})
        self.home_target = info["home_target"]
        self.captured = all(i["captured"] for i in infos)
        self.capture_error = next((i["capture_error"] for i in infos if i["capture_error"]), None)
        self.compile_s = max(i["compile_s"] for i in infos)
        self.capture_s = max(i["capture_s"] for i in infos)
        self.rebuilds = 0
        self._physics_shapes = info["physics_shapes"]
        # Seconds between copies of the shards' states here (0: every step; inf: never).
        self.checkpoint_s = checkpoint_s
        self._checkpoint_at = time.monotonic()  # when the last copies were asked for
        self._checkpoint_refs: tuple[int, dict[int, Any]] | None = None  # (tick, shard → ref)
        self.restored: list[tuple[int, int]] = []  # (shard, tick of the state it came back at)
        # (driver wall seconds, slowest shard's own seconds) of the last step: the difference is
        # what the Ray round trip costs per tick (bench/ray_bench.py reports it).
        self.last_step: tuple[float, float] = (0.0, 0.0)
        self._init_mirror(nworld)  # the faults are kept here: a rebuilt shard keeps its history
        self._staged = StagedCommands(shards)
        self._asked = (-1, -1)  # ticks of the last two snapshot() calls
        self.prefetched = 0  # snapshots that came with their step (diagnostics, bench)
        self._prefetch: tuple[int, dict[int, Any]] | None = None  # (tick, shard → snapshot ref)
        first = ray.get([s.actor.snapshot.remote() for s in self._shards])
        for s, part in zip(self._shards, first, strict=True):
            s.last = part

    def _spawn(self, shard: int) -> Any:
        size = int(self._plan.sizes[shard])
        return RemoteShard.options(**self._options).remote(size, self._kwargs)

    @property
    def actors(self) -> list[Any]:
        """The shards' actor handles, in shard order (diagnostics and fault-injection tests)."""
        return [s.actor for s in self._shards]

    # -- commands: staged per shard, sent with the next step ---------------------------------

    def apply_targets(
        self, worlds: np.ndarray, targets: np.ndarray, velocities: np.ndarray | None = None
    ) -> None:
        self._staged.targets_of(self._plan.split(self._command(worlds, targets, velocities)))

    def reset(self, worlds: np.ndarray) -> None:
        worlds = np.asarray(worlds, dtype=np.int64)
        if worlds.size == 0:
            return
        self._home(worlds)
        self._staged.resets_of(self._plan.split(worlds))

    # -- stepping ---------------------------------------------------------------------------

    def step(self, ticks: int = 1) -> np.ndarray:
        """Advance every shard together; returns the (global) worlds that came back at home."""
        faulted = [self._plan.worlds_of(i) for i in self._revive_ready()]
        t0 = time.perf_counter()
        refs = {}
        for i, s in enumerate(self._shards):
            if s.building is not None:
                continue  # its staged commands wait; it comes back at home anyway
            shipment = self._staged.ship(i, self._targets, self._velocity, self._plan.starts[i])
            refs[i] = s.actor.step.remote(shipment, ticks)
        after = self._tick + ticks
        if self._snapshot_expected(after):
            # Asked for now, the snapshot follows the step's reply at once (an actor runs its
            # calls in order) instead of costing a second round trip after it.
            self._prefetch = (after, {i: self._shards[i].actor.snapshot.remote() for i in refs})
        slowest = 0.0
        for i, ref in refs.items():
            try:
                local, spent = ray.get(ref)
            except RayActorError as exc:
                self._lose(i, exc)
                continue
            slowest = max(slowest, spent)
            faulted.append(local + self._plan.starts[i])
        self.last_step = (time.perf_counter() - t0, slowest)
        self._advance(ticks)
        self._checkpoint()
        out = np.concatenate(faulted) if faulted else np.zeros(0, dtype=np.int64)
        self._home(out)
        self._count_faults(out)
        return out

    def _checkpoint(self) -> None:
        """Keep each shard's state of a recent tick here, so that a lost shard resumes from it.

        The copy is asked for after a step and fetched once it is done (a later tick), so the
        loop never waits for it; only the shard pays its device-to-host copy, once per period.
        """
        if self._checkpoint_refs is not None:
            tick, refs = self._checkpoint_refs
            done, _ = ray.wait(list(refs.values()), num_returns=len(refs), timeout=0)
            if len(done) < len(refs):
                return
            self._checkpoint_refs = None
            for i, ref in refs.items():
                with contextlib.suppress(RayActorError):  # a loss shows at the next step
                    self._shards[i].checkpoint = dataclasses.replace(ray.get(ref), tick=tick)
        if time.monotonic() - self._checkpoint_at < self.checkpoint_s:
            return
        self._checkpoint_at = time.monotonic()
        refs = {
            i: s.actor.get_state.remote(NOTHING)
            for i, s in enumerate(self._shards)
            if s.building is None
        }
        self._checkpoint_refs = (self._tick, refs)

    def _resume(self, shard: int) -> bool:
        """Put the shard's last checkpoint into its new actor, with today's targets; False if
        there is none (the worlds then start at home)."""
        s = self._shards[shard]
        if s.checkpoint is None:
            return False
        lo = int(self._plan.starts[shard])
        hi = lo + int(self._plan.sizes[shard])
        targets = self._targets[lo:hi].copy()
        physics = with_model(s.checkpoint.physics, self._model_state(), lo, hi)
        physics["ctrl"] = targets.astype(physics["ctrl"].dtype)  # what apply_targets would push
        resumed = dataclasses.replace(s.checkpoint, targets=targets, physics=physics)
        ray.get(s.actor.set_state.remote(resumed))
        self.restored.append((shard, s.checkpoint.tick))
        log.warning(
            "Ray shard %d rebuilt; worlds %s resume from tick %d (now %d), with their targets",
            shard,
            self._span(shard),
            s.checkpoint.tick,
            self._tick,
        )
        return True

    def _lose(self, shard: int, exc: BaseException) -> None:
        """The shard's actor is gone: start a new one now; step revives it once it is ready."""
        s = self._shards[shard]
        s.lost.append(time.time())
        log.error("Ray shard %d (worlds %s) lost: %s; rebuilding", shard, self._span(shard), exc)
        with contextlib.suppress(Exception):
            ray.kill(s.actor, no_restart=True)
        self._rebuild(shard)

    def _rebuild(self, shard: int) -> None:
        s = self._shards[shard]
        s.actor = self._spawn(shard)
        s.building = s.actor.info.remote()
        self.rebuilds += 1

    def _revive_ready(self) -> list[int]:
        """Shards whose new actor finished building since the last step (their worlds at home)."""
        revived = []
        for i, s in enumerate(self._shards):
            if s.building is None or s.building is NEVER:
                continue
            done, _ = ray.wait([s.building], timeout=0)
            if not done:
                continue
            try:
                ray.get(s.building)
            except RayActorError as exc:
                s.failures += 1
                s.building = None
                if s.failures >= MAX_REBUILD_ATTEMPTS:
                    log.error("Ray shard %d failed to rebuild %d times: %s", i, s.failures, exc)
                    s.building = NEVER
                else:
                    self._rebuild(i)
                continue
            s.building, s.failures = None, 0
            try:
                resumed = self._resume(i)
            except RayActorError as exc:  # lost again while resuming: start over
                self._lose(i, exc)
                continue
            if resumed:
                continue  # staged commands go with the next step, as for any live shard
            self._staged.take(i)  # commands for the lost worlds are dropped with them
            log.warning("Ray shard %d rebuilt; worlds %s are back at home", i, self._span(i))
            revived.append(i)
        return revived

    def _span(self, shard: int) -> str:
        start = int(self._plan.starts[shard])
        return f"{start}..{start + int(self._plan.sizes[shard]) - 1}"

    # -- reading ----------------------------------------------------------------------------

    def _snapshot_expected(self, tick: int) -> bool:
        """Whether the loop will ask for a snapshot at `tick`: the last two asks were as far
        apart as `tick` is from the last (every tick in fast mode on big batches, every other
        tick at 60 Hz with a 30 Hz stream). A wrong guess costs one unused copy, never a stale
        snapshot: snapshot() uses a prefetch only for the tick it was taken at."""
        before, last = self._asked
        return before >= 0 and tick - last == last - before > 0

    def snapshot(self) -> Snapshot:
        """Every shard's snapshot, joined; a shard being rebuilt shows its last one."""
        if self._tick != self._asked[1]:
            self._asked = (self._asked[1], self._tick)
        ready = self._prefetch[1] if self._prefetch and self._prefetch[0] == self._tick else {}
        self._prefetch = None
        self.prefetched += bool(ready)
        live = [i for i, s in enumerate(self._shards) if s.building is None]
        refs = {
            i: ready[i] if i in ready else self._shards[i].actor.snapshot.remote() for i in live
        }
        for i, ref in refs.items():
            try:
                self._shards[i].last = ray.get(ref)
            except RayActorError as exc:
                self._lose(i, exc)
        parts = [s.last for s in self._shards if s.last is not None]
        joined = SnapshotArrays(
            self._tick,
            np.concatenate([p.sim_time for p in parts]),
            np.concatenate([p.state for p in parts]),
            np.concatenate([p.bodies for p in parts]),
            self._faults.copy(),  # kept here, so that a rebuilt shard keeps its worlds' history
        )
        return snapshot_from(joined, self._targets.copy())

    def qpos(self) -> np.ndarray:
        return self._gather_state()[0]

    def qvel(self) -> np.ndarray:
        return self._gather_state()[1]

    def _gather_state(self) -> tuple[np.ndarray, np.ndarray]:
        if any(s.building is not None for s in self._shards):
            raise RuntimeError("a Ray shard is being rebuilt; its state is not available")
        parts = ray.get([s.actor.state.remote() for s in self._shards])
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def physics_shapes(self) -> dict[str, tuple[int, ...]]:
        """Per-world shape of each physics field of `BatchState` for this model."""
        return dict(self._physics_shapes)

    def _all_live(self, what: str) -> None:
        building = [i for i, s in enumerate(self._shards) if s.building is not None]
        if building:
            raise Unavailable(f"{what}: Ray shard(s) {building} are being rebuilt; try again")

    def get_state(self) -> BatchState:
        """Every shard's state (staged commands applied first), joined in world order."""
        self._all_live("get_state")
        refs = []
        for i, s in enumerate(self._shards):
            shipment = self._staged.ship(i, self._targets, self._velocity, self._plan.starts[i])
            refs.append(s.actor.get_state.remote(shipment))
        try:
            parts = ray.get(refs)
        except RayActorError as exc:
            raise Unavailable(f"get_state: a Ray shard was lost ({exc}); try again") from exc
        joined = join_states(parts, self._targets, self._model_state())
        return dataclasses.replace(joined, tick=self._tick, faults=self._faults.copy())

    def set_state(self, state: BatchState) -> None:
        """Split `state` over the shards; checked whole first so no shard is half-restored."""
        state.check_compatible(self.nworld, self._physics_shapes)
        model = self._check_model_state(state)
        self._all_live("set_state")
        for i in range(self.shards):
            self._staged.take(i)  # staged commands belonged to the state being replaced
        bounds = [*self._plan.starts.tolist(), self.nworld]
        refs = [
            s.actor.set_state.remote(slice_state(state, bounds[i], bounds[i + 1]))
            for i, s in enumerate(self._shards)
        ]
        try:
            ray.get(refs)
        except RayActorError as exc:
            raise Unavailable(f"set_state: a Ray shard was lost ({exc}); try again") from exc
        self._restore_mirror(state, model)  # the shards took their slices of `model`
        self._prefetch, self._asked = None, (-1, -1)
        self._checkpoint_refs = None  # copies of the replaced state
        parts = ray.get([s.actor.snapshot.remote() for s in self._shards])
        for s, part in zip(self._shards, parts, strict=True):
            s.last = part

    def write_state(self, write: StateWrite) -> None:
        """Staged for the shard that holds the world, sent with its next step."""
        shard, local = self._plan.locate(write.world)
        self._staged.state(shard, write.moved(local))

    def push_model(self, field: str, worlds: np.ndarray) -> None:
        """Staged for the shards holding the worlds, sent with their next step."""
        rows = self._model_rows(field, worlds)
        stage_model(self._plan, self._staged, field, rows, worlds)

    def write_qpos(self, world: int, qpos: np.ndarray) -> None:
        """Overwrite one world's qpos now (fault-injection tests), on the shard that holds it."""
        shard, local = self._plan.locate(world)
        actor = self._shards[shard].actor
        # Commands staged before this call happen before it, as on a WorldBatch: send them
        # with a step of zero ticks first (an actor runs its calls in order).
        start = self._plan.starts[shard]
        actor.step.remote(self._staged.ship(shard, self._targets, self._velocity, start), 0)
        ray.get(actor.write_qpos.remote(local, np.asarray(qpos)))

    def close(self) -> None:
        """Stop every shard's actor (the Ray connection stays for others in this process)."""
        for s in self._shards:
            with contextlib.suppress(Exception):
                ray.kill(s.actor, no_restart=True)
