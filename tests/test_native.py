"""`armfleet serve --engine mujoco`: the native engine behind the real service, over sockets.

The engine's behaviour (targets, resets, faults, grasp, fidelity) is tested with the warp
engine's in tests/test_engine.py; this checks that the service runs it end to end.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import httpx
import numpy as np
import pytest
from conftest import ELBOW, HOME, Server, serve, wait_for
from websockets.sync.client import connect

from service.core.streams import wire
from service.engines.cores import usable_cores
from service.engines.native import NativeBatch, auto_threads


def test_native_batch_uses_every_usable_core_once_the_batch_is_big_enough():
    assert NativeBatch(8).nthread == 1  # a few worlds: the pool would cost more than it brings
    assert NativeBatch(64).nthread == min(2, usable_cores())
    assert auto_threads(4096) == usable_cores()
    assert NativeBatch(8, nthread=2).nthread == 2
    assert NativeBatch(1, nthread=4).nthread == 1  # no more threads than worlds


def test_native_snapshot_is_float32_and_c_ordered_like_the_warp_engines():
    """The wire serialises rows of these arrays: they must be C-ordered, and float32 keeps the
    frames the size the warp engine's are."""
    batch = NativeBatch(3)
    batch.step(1)
    snap = batch.snapshot()
    for name in ("position", "velocity", "effort", "flange_pos", "flange_quat"):
        array = getattr(snap, name)
        assert array.dtype == np.float32 and array.flags.c_contiguous, name
    assert snap.target.dtype == np.float64  # what was commanded, exactly
    frame = json.loads(wire.single_frame(snap, 2, batch.spec.names))
    assert frame["position"] == pytest.approx(snap.position[2].tolist())


def test_native_engine_refuses_a_gpu_device():
    with pytest.raises(ValueError, match="CPU only"):
        NativeBatch(1, device="cuda")


@pytest.fixture(scope="module")
def native_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    log_dir = tmp_path_factory.mktemp("native")
    with serve(worlds=4, extra_args=("--engine", "mujoco"), log_dir=log_dir) as srv:
        yield srv


def test_service_runs_the_native_engine_end_to_end(native_server):
    srv = native_server
    with httpx.Client(base_url=srv.url, timeout=10) as http:
        info = http.get("/v1/info").json()
        assert "native MuJoCo" in info["device"]
        assert info["substeps"] * info["physics_dt"] == pytest.approx(1 / 60)

        with connect(f"{srv.ws_url}/v1/ws/worlds/3?rate=30") as ws:
            ws.send('{"op": "increment", "joint": "elbow_joint", "delta": 0.2, "id": 1}')
            ack = wait_for(lambda: _next_ack(ws), "the increment's ack")
            assert ack["target"][ELBOW] == pytest.approx(HOME[ELBOW] + 0.2)

        def moved() -> bool:
            position = http.get("/v1/worlds/3/state").json()["position"]
            return abs(position[ELBOW] - (HOME[ELBOW] + 0.2)) < 0.01

        wait_for(moved, "world 3's elbow to reach its new target")
        states = http.get("/v1/worlds/state").json()["worlds"]
        others = np.array([s["position"][ELBOW] for s in states[:3]])
        np.testing.assert_allclose(others, HOME[ELBOW], atol=1e-3)  # the others did not move
        assert all(s["faults"] == 0 for s in states)

        http.post("/v1/worlds/3/reset").raise_for_status()
        wait_for(
            lambda: http.get("/v1/worlds/3/state").json()["target"][ELBOW] == HOME[ELBOW],
            "world 3's reset",
        )


def test_a_slow_stream_gets_the_frame_carrying_its_command_at_once(native_server):
    """At rate=0.2 the next regular frame is 5 s away; the one carrying an acked command is not
    held back for it: it is the first frame after the ack, from the command's own tick."""
    with connect(f"{native_server.ws_url}/v1/ws/worlds/1?rate=0.2") as ws:
        first = json.loads(ws.recv(timeout=5))
        assert first["op"] == "state"
        ws.send('{"op": "increment", "joint": "wrist_3_joint", "delta": 0.1, "id": 7}')
        ack = json.loads(ws.recv(timeout=5))
        assert ack["op"] == "ack" and ack["id"] == 7
        frame = json.loads(ws.recv(timeout=5))
        assert frame["op"] == "state" and frame["tick"] >= ack["tick"]
        assert frame["target"] == ack["target"]
        # Not the regular frame 5 s (300 ticks) later: a few ticks at most after the command's.
        assert frame["tick"] - ack["tick"] < 30, (frame["tick"], ack["tick"])


def _next_ack(ws) -> dict | None:
    msg = json.loads(ws.recv(timeout=5))
    return msg if msg.get("op") == "ack" else None


def test_the_whole_batch_check_finds_exactly_the_worlds_the_per_world_check_finds():
    """After a tick the engine tests whole arrays first and world by world only when that fails:
    a state past the quick test's bound that is not bad resets nobody, and a bad world among
    them is still found, alone."""
    a = NativeBatch(4, nthread=2)
    cube = a.robot.mjm.joint("cube_joint")
    q = a.qpos()[2]
    q[cube.qposadr[0]] = 2.0e4  # the cube 20 km away: absurd, finite, not a fault
    a.write_qpos(2, q)
    assert a.step(3).tolist() == []
    assert a.qpos()[2, cube.qposadr[0]] > 1.0e4  # still there: it was not reset
    a._qvel[1, 0] = 2.0e4  # shoulder_pan past the divergence bound (MuJoCo's own is 1e10)
    assert a.step(1).tolist() == [1]
    assert a.snapshot().faults.tolist() == [0, 1, 0, 0]
    a.write_qpos(3, np.full(a.qpos().shape[1], np.nan))  # MuJoCo resets it and warns
    assert a.step(2).tolist() == [3]
    a.reset(np.array([2]))
    assert a.step(2).tolist() == []
    assert a.snapshot().faults.tolist() == [0, 1, 0, 1]
    a.close()


def test_frames_and_snapshots_read_the_state_as_written_and_keep_their_own_tick():
    """The engine copies every world's qpos|qvel once per state for the fault check, frames and
    snapshots (`_rows_now`), and reads the effort once when asked: a write between two ticks
    (a state slice, a reset, a restore) shows in the next snapshot, and a frame packed at one
    tick but built on the frame thread after the next tick still carries its own tick's state."""
    from service.core.sim.batch import StateWrite
    from service.core.streams import frames

    a, fresh = NativeBatch(3, nthread=2), NativeBatch(3, nthread=2)
    names, ids, adr = a.spec.names, np.arange(3), a.robot.qpos_adr
    a.apply_targets(ids, np.tile(a.home_target + 0.2, (3, 1)))  # the arms move: every tick differs
    a.step(4)
    snap, packed = a.snapshot(), a.pack_rows(ids)
    saved = a.get_state()
    a.step(2)  # the next ticks step before the frame thread builds the rows
    data = frames.FrameData(packed)
    assert frames.binary(data, packed.wait(), names) == wire.batch_frame_binary(snap, ids, names)
    assert not np.array_equal(a.snapshot().position, snap.position)

    a.write_state(StateWrite("qpos", 1, adr[2:3], np.array([-1.0])))  # between two ticks
    assert a.snapshot().position[1, 2] == np.float32(-1.0)
    assert a.pack_rows(ids).wait()[1, 1 + 2] == np.float32(-1.0)
    a.reset(np.array([2]))  # home, with the effort the reset's forward pass computes
    home = fresh.snapshot()
    np.testing.assert_array_equal(a.snapshot().position[2], home.position[2])
    np.testing.assert_array_equal(a.snapshot().effort[2], home.effort[2])
    a.set_state(saved)  # the restored state's own effort, until the next step
    np.testing.assert_array_equal(a.snapshot().position, snap.position)
    np.testing.assert_array_equal(a.snapshot().effort, snap.effort)
    a.reset(np.array([0]))  # a reset after a restore keeps the others' restored effort
    np.testing.assert_array_equal(a.snapshot().effort[1:], snap.effort[1:])
    np.testing.assert_array_equal(a.snapshot().effort[0], home.effort[0])
