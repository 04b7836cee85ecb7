"""Packed batch frames (service.frames): the same bytes as frames cut from a snapshot, and the
same state as HTTP reports, bit for bit, on every engine that packs its own rows.

The engine-level checks compare `frames.binary` / `frames.json` of `pack(batch, ids)` with
`wire.batch_frame_binary` / `wire.batch_frame` of `batch.snapshot()` after commands, a reset, a
fault and a restore (each of which moves one of the columns the engines keep mirrors of). The
end-to-end check subscribes over a real socket to a subset of worlds of a real server, steps it,
and compares the frames with GET /v1/worlds/state of the same tick. With a CUDA device, the warp
engine is also checked there.
"""

from __future__ import annotations

import json
from dataclasses import replace

import httpx
import numpy as np
import pytest
from conftest import HOME, JOINTS
from websockets.sync.client import connect

from clients import ArmfleetClient, point
from clients.stream import parse_binary_states
from clients.testing import serve
from service.core.sim import safety
from service.core.streams import frames, wire
from service.engines.native import NativeBatch
from service.engines.warp import WorldBatch

NWORLD = 6
IDS = np.array([1, 3, 4])


def _devices() -> list[str]:
    import warp as wp

    return ["cpu", "cuda"] if wp.is_cuda_available() else ["cpu"]


ENGINES = {
    "mujoco": lambda: NativeBatch(NWORLD, nthread=2),
    **{f"warp-{d}": (lambda d=d: WorldBatch(NWORLD, device=d)) for d in _devices()},
}


@pytest.fixture(scope="module", params=sorted(ENGINES))
def batch(request: pytest.FixtureRequest):
    b = ENGINES[request.param]()
    yield b
    b.close()


def _check_same_bytes(batch, ids: np.ndarray) -> None:
    names = batch.spec.names
    data = frames.pack(batch, ids, json=True)
    assert data is not None
    rows = data.packed.wait()
    try:
        snap = batch.snapshot()
        assert data.tick == snap.tick
        assert frames.binary(data, rows, names) == wire.batch_frame_binary(snap, ids, names)
        assert frames.json(data, rows, names) == wire.batch_frame(snap, ids, names)
    finally:
        data.packed.release()


def test_packed_frames_are_the_snapshot_frames_byte_for_byte(batch):
    batch.reset(np.arange(NWORLD))
    targets = np.tile(batch.home_target, (NWORLD, 1))
    targets[:, 1] -= 0.1 * np.arange(NWORLD)  # a different pose per world
    batch.apply_targets(np.arange(NWORLD), targets)
    batch.step(5)
    _check_same_bytes(batch, IDS)
    # A velocity feed-forward (trajectories) goes into ctrl, never into the reported target.
    batch.apply_targets(IDS, targets[IDS], velocities=np.full((len(IDS), 7), 0.05))
    batch.step(2)
    _check_same_bytes(batch, IDS)
    _check_same_bytes(batch, np.arange(NWORLD))  # every world, in order
    state = batch.get_state()
    batch.reset(np.array([3]))  # sim_time restarts, targets go home
    batch.step(2)
    _check_same_bytes(batch, IDS)
    batch.write_qpos(4, np.full(batch.qpos().shape[1], np.nan))  # a fault: counted and reset
    batch.step(1)
    assert batch.snapshot().faults[4] >= 1
    _check_same_bytes(batch, IDS)
    batch.set_state(state)  # the mirrors of ticks and faults follow a restore
    _check_same_bytes(batch, IDS)
    batch.step(1)
    _check_same_bytes(batch, IDS)


def test_large_json_frames_are_sliced_without_changing_a_byte(batch, monkeypatch):
    monkeypatch.setattr(frames, "JSON_SLICE", 2)  # 6 worlds: three slices per column
    batch.step(1)
    _check_same_bytes(batch, np.arange(NWORLD))


def test_json_frames_reuse_steady_columns_only_while_bit_for_bit_the_same(batch):
    """Targets, faults and world ids keep last frame's text while their bytes are unchanged
    (frames._steady_array); a target moved by one ulp, or another selection, is written anew."""
    batch.step(1)
    _check_same_bytes(batch, IDS)
    batch.step(1)
    _check_same_bytes(batch, IDS)  # the same targets: last frame's text, the same bytes
    targets = batch.snapshot().target[IDS]
    targets[1, 2] = np.nextafter(targets[1, 2], np.inf)
    batch.apply_targets(IDS, targets)
    batch.step(1)
    _check_same_bytes(batch, IDS)
    _check_same_bytes(batch, IDS[:2])  # another selection of the same width


def test_binary_frames_end_with_each_worlds_safety_mode(batch):
    """Layout 2: the safety block after the rows, the same bytes packed or cut from the
    snapshot; the client names the modes, and reads a layout-1 frame (an older server's: no
    `layout`, no block) to the same state with no safety mode."""
    names = batch.spec.names
    modes = np.full(NWORLD, safety.NORMAL, dtype=np.int8)
    modes[3] = safety.PROTECTIVE_STOP
    batch.step(1)
    data = frames.pack(batch, IDS, json=False)
    assert data is not None
    data.safety = modes[IDS]  # as the hub sets it from the loop's safety table
    rows = data.packed.wait()
    try:
        snap = replace(batch.snapshot(), safety=modes)
        got = bytes(frames.binary(data, rows, names))
        assert got == wire.batch_frame_binary(snap, IDS, names)
    finally:
        data.packed.release()
    assert got[-len(IDS) :] == bytes([1, 3, 1])  # IDS 1, 3, 4: UR's numbers
    hlen = int.from_bytes(got[4:8], "little")
    header = json.loads(got[8 : 8 + hlen])
    assert header["layout"] == wire.BINARY_LAYOUT == 2
    assert len(got) == 8 + hlen + 4 * len(IDS) * (1 + 37) + len(IDS)
    states = parse_binary_states(got)
    assert states.safety_mode == ("NORMAL", "PROTECTIVE_STOP", "NORMAL")
    assert states.world(3).safety_mode == "PROTECTIVE_STOP"
    del header["layout"]
    old_header = json.dumps(header).encode()
    old = b"".join(
        (got[:4], len(old_header).to_bytes(4, "little"), old_header, got[8 + hlen : -len(IDS)])
    )
    older = parse_binary_states(old)
    assert older.safety_mode is None and older.world(3).safety_mode == "NORMAL"
    np.testing.assert_array_equal(older.position, states.position)
    assert older.tick == states.tick and older.worlds.tolist() == IDS.tolist()


def _binary_rows(frame: bytes) -> tuple[dict, np.ndarray, np.ndarray]:
    hlen = int.from_bytes(frame[4:8], "little")
    header = json.loads(frame[8 : 8 + hlen])
    n = header["n"]
    ids = np.frombuffer(frame, "<i4", n, 8 + hlen)
    rows = np.frombuffer(frame, "<f4", n * 37, 8 + hlen + 4 * n).reshape(n, 37)
    return header, ids, rows


def _frame_of(ws, tick_wanted: int) -> str | bytes:
    """The frame of `tick_wanted` (a stream without a rate sends one of every tick)."""
    while True:
        msg = ws.recv(timeout=10)
        if isinstance(msg, bytes):
            tick = _binary_rows(msg)[0]["tick"]
        else:
            parsed = json.loads(msg)
            if parsed.get("op") != "states":
                continue
            tick = parsed["tick"]
        if tick >= tick_wanted:
            return msg


SERVED = {"mujoco": ("--engine", "mujoco")} | {
    f"warp-{d}": ("--engine", "warp", "--device", d) for d in _devices()
}


@pytest.mark.parametrize("engine", sorted(SERVED))
def test_streamed_frames_carry_the_http_state_bit_for_bit(tmp_path, engine):
    with serve(worlds=NWORLD, mode="paused", extra_args=SERVED[engine], log_dir=tmp_path) as s:
        http = httpx.Client(base_url=s.url, timeout=30)
        http.put("/v1/worlds/3/targets", json={"name": ["elbow_joint"], "position": [1.2]})
        http.post("/v1/worlds/4/reset").raise_for_status()
        # World 1 follows a trajectory: its targets move with a velocity feed-forward in ctrl,
        # and JSON frames carry its progress.
        arm = ArmfleetClient(s.url)
        goal = (np.array(HOME[:6]) + 0.2).tolist()
        started = arm.start_trajectory(1, JOINTS[:6], [point(goal, 1.0)])
        spec = "1,3-4"
        with (
            connect(f"{s.ws_url}/v1/ws?worlds={spec}&format=binary") as wb,
            connect(f"{s.ws_url}/v1/ws?worlds={spec}") as wj,
        ):
            first = _binary_rows(wb.recv(timeout=10))[0]["tick"]  # the current state at once
            wj.recv(timeout=10)
            http.post("/v1/sim/step", json={"ticks": 4}).raise_for_status()
            as_binary = _frame_of(wb, first + 4)
            header, ids, rows = _binary_rows(as_binary)
            as_json = json.loads(_frame_of(wj, first + 4))
            state = http.get("/v1/worlds/state", params={"worlds": spec}).json()
            status = arm.trajectory(1)
    assert header["tick"] == as_json["tick"] == state["tick"] == first + 4
    assert ids.tolist() == as_json["worlds"] == [w["world"] for w in state["worlds"]] == [1, 3, 4]
    columns = {
        name: (sum(w for _, w in wire.BINARY_COLUMNS[:i]), width)
        for i, (name, width) in enumerate(wire.BINARY_COLUMNS)
    }
    http_cols = {
        "sim_time": [w["sim_time"] for w in state["worlds"]],
        "position": [w["position"] for w in state["worlds"]],
        "velocity": [w["velocity"] for w in state["worlds"]],
        "effort": [w["effort"] for w in state["worlds"]],
        "target": [w["target"] for w in state["worlds"]],
        "flange_position": [w["flange"]["position"] for w in state["worlds"]],
        "flange_quaternion": [w["flange"]["quaternion"] for w in state["worlds"]],
        "faults": [w["faults"] for w in state["worlds"]],
    }
    for name, values in http_cols.items():
        start, width = columns[name]
        got = rows[:, start : start + width].reshape(len(values), -1)
        want = np.asarray(values, dtype=np.float64).reshape(len(values), -1).astype(np.float32)
        np.testing.assert_array_equal(got, want, err_msg=name)  # float32 of HTTP's numbers
        assert as_json[name] == values, name  # the same JSON numbers
    modes = tuple(w["safety_mode"] for w in state["worlds"])  # HTTP's, by name
    assert parse_binary_states(as_binary).safety_mode == modes == tuple(as_json["safety_mode"])
    assert as_json["target"][1][2] == pytest.approx(1.2)
    assert status.state == "running" and 0 < status.progress < 1
    assert as_json["trajectories"] == {
        "1": {"id": started.id, "state": "running", "reason": None, "progress": status.progress}
    }


def test_the_frame_thread_and_its_helper_process_deliver_the_same_bytes(monkeypatch):
    """Big JSON frames go to a helper process, binary ones are joined on the frame thread."""
    import queue

    monkeypatch.setattr(frames, "BIG_JSON_ROWS", 2)
    batch = NativeBatch(NWORLD, nthread=1)
    batch.step(3)
    names = batch.spec.names
    got: queue.Queue = queue.Queue()
    sender = frames.FrameSender(lambda job, out: got.put(out))
    try:
        data = frames.pack(batch, IDS, json=True)
        assert data is not None
        sender.submit(frames.Job(data, ["binary", "json"], None, names))
        out = got.get(timeout=60)  # each format is delivered when it is ready
        out.update(got.get(timeout=60))
    finally:
        sender.stop()
    snap = batch.snapshot()
    assert out["binary"] == wire.batch_frame_binary(snap, IDS, names)
    assert out["json"] == wire.batch_frame(snap, IDS, names)
