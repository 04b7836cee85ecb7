"""Replay: rebuild a recording's batch, re-apply its commands at their ticks, compare bit for bit.

The recording (`mcap_log.py`) holds the batch header, the full starting state, every
accepted command with its effective tick, every restore with the restored state, and states of
some worlds at some ticks. Replay builds a batch of the same model and size, restores the
starting state into a paused loop, and then, tick by tick, stages the recorded commands through
the control layer (source `replay`) exactly where they took effect and steps; at every recorded
tick it compares position, velocity and effort of every recorded world: with `==` on float64
where the replay can be bit-exact, within a stated tolerance elsewhere (`replay_check`).
The first difference names the tick, world, joint and quantity. Going through the same loop and
control code as the live service means the same staging rules (resets before targets, the last
target of a tick wins) apply, instead of a second implementation of them.
"""

from __future__ import annotations

import copy
import json
import logging
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from mcap.records import Attachment, Channel, Message, Metadata
from mcap.stream_reader import StreamReader

from service.core.access.policy import ClientSlots
from service.core.access.settings import AccessSettings
from service.core.commands.base import REPLAY
from service.core.commands.control import Control
from service.core.commands.registry import BY_KIND
from service.core.metrics import Metrics
from service.core.sim.loop import SimLoop
from service.core.sim.physics import configure
from service.core.sim.robot import LoadedRobot, load_robot
from service.core.sim.types import BatchState, Mode
from service.core.surface import SurfaceContext
from service.persistence.mcap_log import (
    COMMANDS,
    METADATA,
    RESTORES,
    decode_joint_state,
    parse_metadata,
    tick_of,
)
from service.persistence.provenance import batch_header, mismatch, model_hash
from service.persistence.recorder import Recorder
from service.persistence.replay_check import (
    TOLERANCE,
    Comparison,
    DeviationRange,
    Divergence,
    Tolerance,
    bit_exact,
    table_span,
)
from service.persistence.snapshots import decode_state

log = logging.getLogger("armfleet.replay")

__all__ = ["Divergence", "ReplayError", "ReplayReport", "read_recording", "replay"]


class ReplayError(RuntimeError):
    """The recording cannot be replayed (unreadable, no metadata, another model, ...)."""


@dataclass
class Segment:
    """A stretch of the recording between restores: where it starts and what happened in it."""

    start: BatchState
    commands: dict[int, list[dict[str, Any]]] = field(default_factory=lambda: defaultdict(list))
    states: dict[int, dict[int, tuple[np.ndarray, ...]]] = field(
        default_factory=lambda: defaultdict(dict)
    )
    end_tick: int | None = None  # the tick at which a restore ended it


@dataclass
class Recording:
    path: str
    header: dict[str, Any]
    segments: list[Segment]
    names: list[str]
    worlds: list[int]
    rate: float
    truncated: str | None = None


@dataclass(frozen=True)
class ReplayReport:
    """What a replay did: ticks stepped, states and commands, wall time, the first divergence."""

    path: str
    nworld: int
    ticks: int
    states_compared: int
    commands: int
    restores: int
    wall_s: float
    divergence: Divergence | None
    truncated: str | None
    out: str | None
    recorded_on: str = ""
    replayed_on: str = ""
    tolerance: Tolerance | None = None  # None: compared bit for bit
    deviations: list[DeviationRange] = field(default_factory=list)  # largest per tick range
    largest: dict[str, float] = field(default_factory=dict)  # largest over the whole replay

    @property
    def ticks_per_s(self) -> float:
        return self.ticks / self.wall_s if self.wall_s > 0 else 0.0


def read_recording(path: Path | str) -> Recording:
    """Parse a recording in file order (the order things happened), checking CRCs."""
    header: dict[str, Any] | None = None
    attachments: dict[str, bytes] = {}
    channels: dict[int, str] = {}
    events: list[tuple[str, Any]] = []
    truncated = None
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, validate_crcs=True).records:
                if isinstance(record, Metadata) and record.name == METADATA:
                    header = parse_metadata(record.metadata)
                elif isinstance(record, Attachment):
                    attachments[record.name] = record.data
                elif isinstance(record, Channel):
                    channels[record.id] = record.topic
                elif isinstance(record, Message):
                    events.append((channels[record.channel_id], record))
        except Exception as exc:  # a recording cut short (crash, kill): use what was read
            truncated = f"{type(exc).__name__}: {exc}"
    if header is None:
        raise ReplayError(f"{path}: no '{METADATA}' metadata record; not an armfleet recording")
    names = list(header["joint_names"])
    hz = float(header["control_hz"])

    def state(name: str) -> BatchState:
        if name not in attachments:
            raise ReplayError(f"{path}: attachment {name!r} missing (truncated recording?)")
        return decode_state(attachments[name])

    segments = [Segment(state(header["start_state"]))]
    for topic, msg in events:
        seg = segments[-1]
        if topic == COMMANDS:
            body = json.loads(msg.data)
            if BY_KIND[body["kind"]].replayed:
                seg.commands[int(body["tick"])].append(body)
        elif topic == RESTORES:
            body = json.loads(msg.data)
            seg.end_tick = int(body["tick_before"])
            segments.append(Segment(state(body["attachment"])))
        elif topic.endswith("/joint_states") and topic.startswith("/world_"):
            world = int(topic[len("/world_") : -len("/joint_states")])
            stamp, msg_names, pos, vel, eff = decode_joint_state(msg.data)
            if msg_names != names:
                raise ReplayError(f"{topic}: joint names {msg_names} differ from {names}")
            seg.states[tick_of(stamp, hz)][world] = (pos, vel, eff)
    worlds = [int(w) for w in header["worlds"]]
    rate = float(header["rate"])
    return Recording(str(path), header, segments, names, worlds, rate, truncated)


Judgement = Tolerance | Literal["auto", "exact"]


def replay(
    path: Path | str,
    out: Path | str | None = None,
    device: str | None = None,
    tolerance: Judgement = "auto",
    scene: Path | str | None = None,
) -> ReplayReport:
    """Replay `path` (see the module doc); `out` also writes the replayed run as a recording;
    `scene`: the cell it was recorded with (`serve --scene`), None for the default one.

    tolerance: "auto" compares bit for bit where the replay can be bit-exact (recorded and
    replayed on the CPU) and within `replay_check.TOLERANCE` elsewhere; "exact" always bit for
    bit; a Tolerance, within it.
    """
    return replay_recording(read_recording(path), out, device, tolerance, scene)


def replay_recording(
    rec: Recording,
    out: Path | str | None = None,
    device: str | None = None,
    tolerance: Judgement = "auto",
    scene: Path | str | None = None,
) -> ReplayReport:
    """Replay a parsed recording (tests change one on purpose to see divergence named)."""
    path = rec.path
    h = rec.header
    robot = load_robot() if scene is None else load_robot(scene)
    _check_model(rec, robot)

    from service.engines.warp import WorldBatch

    batch = WorldBatch(
        int(h["nworld"]),
        device=device or "cpu",
        control_hz=float(h["control_hz"]),
        physics_dt=float(h["physics_dt"]),
        robot=robot,
    )
    if why := mismatch(h, batch_header(batch)):
        batch.close()
        raise ReplayError(f"{path}: cannot replay here: {why}")
    if tolerance == "auto":
        same = str(h.get("device", "")) == batch.device_name
        tolerance = "exact" if same and bit_exact(batch.device_name) else TOLERANCE
    ticks = [t for seg in rec.segments for t in seg.states]
    first = rec.segments[0].start.tick
    compare = Comparison(
        rec.names,
        None if tolerance == "exact" else tolerance,
        table_span(first, max(ticks, default=first)),
    )
    loop = SimLoop(batch, Mode.PAUSED)
    control = Control(loop)
    loop.start()
    recorder = None
    try:
        t0 = time.perf_counter()
        loop.state_door.restore(rec.segments[0].start, "start").result()
        if out is not None:  # the replayed run, recorded like the live one (from the same state)
            recorder = Recorder(out, rec.worlds, rec.rate, block=True)
            recorder.start(_context(loop, control))
        counts = {"ticks": 0, "states": 0, "commands": 0}
        for i, seg in enumerate(rec.segments):
            if i:
                loop.state_door.restore(seg.start, "restore").result()
            _replay_segment(loop, control, seg, compare, counts)
        wall = time.perf_counter() - t0
    finally:
        if recorder is not None:
            recorder.stop()
        loop.stop()
        batch.close()
    return ReplayReport(
        path=str(path),
        nworld=batch.nworld,
        ticks=counts["ticks"],
        states_compared=counts["states"],
        commands=counts["commands"],
        restores=len(rec.segments) - 1,
        wall_s=wall,
        divergence=compare.divergence,
        truncated=rec.truncated,
        out=None if out is None else str(out),
        recorded_on=str(h.get("device", "")),
        replayed_on=batch.device_name,
        tolerance=compare.tolerance,
        deviations=compare.rows(),
        largest=compare.largest(),
    )


def _check_model(rec: Recording, robot: LoadedRobot) -> None:
    """ReplayError when the recording was made from another model than `robot`'s (another
    cell, a changed MJCF or MuJoCo), found from the compiled model before MuJoCo Warp is loaded
    and built (~5 CPU-s). The model is hashed at the recording's own step; the batch built
    afterwards is checked against the whole header (worlds, step) as well."""
    h = rec.header
    mjm = copy.copy(robot.mjm)
    configure(mjm, float(h["physics_dt"]))  # the solver: model_hash hashes every one as CG
    here = {k: h.get(k) for k in ("nworld", "substeps", "physics_dt")}
    if why := mismatch(h, {**here, "model_hash": model_hash(mjm)}):
        raise ReplayError(f"{rec.path}: cannot replay here: {why}")


def _context(loop: SimLoop, control: Control) -> SurfaceContext:
    """The context a surface gets in a service, for the recorder that writes the replayed run:
    the same loop and control; no sockets (no hub, no clients), metrics nobody reads."""
    return SurfaceContext(loop, control, None, AccessSettings(), ClientSlots(0), Metrics())


def _replay_segment(
    loop: SimLoop, control: Control, seg: Segment, compare: Comparison, counts: dict[str, int]
) -> None:
    """Step one segment with its commands, comparing every recorded state (all of them, also
    after a divergence: the deviation table shows how differences develop)."""
    tick = seg.start.tick
    last = seg.end_tick if seg.end_tick is not None else max([tick, *seg.states, *seg.commands])
    while tick < last:
        for cmd in seg.commands.get(tick + 1, ()):
            _apply(control, cmd)
            counts["commands"] += 1
        tick = loop.step(1).result()
        counts["ticks"] += 1
        recorded = seg.states.get(tick)
        if recorded:
            snap = loop.latest
            assert snap.tick == tick
            worlds = np.array(sorted(recorded))
            want = np.array([recorded[w] for w in worlds], dtype=np.float64)  # (k, 3, 7)
            got = np.stack([snap.position[worlds], snap.velocity[worlds], snap.effort[worlds]], 1)
            counts["states"] += len(worlds)
            compare.check(tick, worlds, want, got.astype(np.float64))


def _apply(control: Control, cmd: dict[str, Any]) -> None:
    """Re-apply one recorded command as its class says (service.core.commands.registry)."""
    control.run(BY_KIND[cmd["kind"]].from_record(control, cmd), REPLAY)
