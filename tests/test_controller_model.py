"""The controllers' view model without widgets or network: what the rows and status show."""

from __future__ import annotations

import numpy as np
from conftest import HOME, JOINTS

from clients import CommandAck, ConnectionStatus, Info, JointInfo, ResetResult, WorldState
from clients.apps.controller import ControllerModel, Notice

URL = "http://127.0.0.1:8000"


def state(world: int, tick: int, target: list[float], position: list[float] | None = None):
    return WorldState(
        world=world,
        tick=tick,
        sim_time=tick / 60,
        name=JOINTS,
        position=np.array(position or target),
        velocity=np.zeros(7),
        effort=np.zeros(7),
        target=np.array(target),
        flange_position=np.zeros(3),
        flange_quaternion=np.array([1.0, 0, 0, 0]),
        faults=0,
    )


def ack(world: int, tick: int, target: list[float], clamped: tuple[str, ...] = ()) -> CommandAck:
    return CommandAck(world=world, target=np.array(target), clamped=clamped, tick=tick)


def info(nworld: int = 4) -> Info:
    pairs = zip(JOINTS, HOME, strict=True)
    joints = tuple(JointInfo(n, -6.28, 6.28, h, 2.0, 100.0) for n, h in pairs)
    return Info(
        robot="UR10e",
        joints=joints,
        nworld=nworld,
        device="cpu",
        shards=1,
        control_hz=60.0,
        physics_dt=0.002,
        substeps=8,
        mode="realtime",
        tick=0,
        sim_time=0.0,
        ticks_per_s=60.0,
        realtime_factor=1.0,
        captured=True,
    )


def test_rows_come_from_the_served_model_and_start_without_values() -> None:
    m = ControllerModel(URL, 1)
    assert m.names == [] and m.selected_joint() is None  # nothing known before /v1/info
    assert m.move_selection(1) == 0
    assert m.status_text() == f"{URL}: connecting to {URL}..."
    m.apply(info())
    assert [m.joint_label(i) for i in range(7)][2] == "[2] elbow_joint"
    assert m.target_text(0) == "--" and m.measured_text(0) == "--"
    assert m.move_selection(-1) == 6 and m.selected_joint() == JOINTS[6]


def test_target_shows_the_replied_value_and_older_frames_do_not_undo_it() -> None:
    m = ControllerModel(URL, 1)
    m.apply(state(1, 100, HOME))
    up = list(HOME)
    up[2] = 1.67
    m.apply(ack(1, 102, up))
    assert m.target_text(2) == "1.67"
    m.apply(state(1, 101, HOME))  # stepped before the command took effect
    assert m.target_text(2) == "1.67"
    m.apply(state(1, 102, up, position=[*HOME[:2], 1.6, *HOME[3:]]))
    assert m.target_text(2) == "1.67" and m.measured_text(2) == "1.60"


def test_negative_zero_shows_as_zero() -> None:
    m = ControllerModel(URL, 0)
    m.apply(state(0, 1, HOME, position=[-1e-9, *HOME[1:]]))
    assert m.measured_text(0) == "0.00"


def test_clamped_reply_is_reported_on_the_status_line() -> None:
    m = ControllerModel(URL, 1)
    m.apply(state(1, 10, HOME))
    m.apply(ack(1, 11, [*HOME[:6], 0.7], clamped=("finger_joint",)))
    assert "clamped at the joint limit: finger_joint" in m.status_text()
    assert m.target_text(6) == "0.70"


def test_status_says_server_gone_then_recovers() -> None:
    m = ControllerModel(URL, 1)
    m.apply(info())
    m.apply(ConnectionStatus(True, "ws://x"))
    m.apply(state(1, 500, HOME))
    assert m.status_text() == f"Connected to {URL}: world 1 (0..3), tick 500"
    m.apply(ConnectionStatus(False, "connection refused", attempt=2, retry_in=0.4))
    assert not m.connected
    assert "server gone (connection refused); retrying in 0.4 s" in m.status_text()
    m.apply(ConnectionStatus(True, "ws://x"))
    m.apply(state(1, 3, HOME))  # a restarted server counts from tick 0 again
    assert m.status_text().startswith(f"Connected to {URL}: world 1")
    assert m.tick == 3


def test_switching_world_ignores_late_frames_of_the_old_one() -> None:
    m = ControllerModel(URL, 1)
    m.apply(info(4))
    m.apply(state(1, 10, HOME))
    m.select_world(m.clamp_world(2))
    assert m.target_text(2) == "--"
    m.apply(state(1, 11, HOME))
    assert m.target_text(2) == "--"
    m.apply(state(2, 11, [*HOME[:2], 0.5, *HOME[3:]]))
    assert m.target_text(2) == "0.50"
    assert m.clamp_world(4) == 0 and m.clamp_world(-1) == 3


def test_reset_shows_home_targets_and_a_notice() -> None:
    m = ControllerModel(URL, 1)
    m.apply(info())
    m.apply(state(1, 10, [*HOME[:2], 0.3, *HOME[3:]]))
    m.apply(ResetResult(worlds=(1,), tick=12))
    assert m.target_text(2) == "1.57"
    m.apply(state(1, 11, [*HOME[:2], 0.3, *HOME[3:]]))  # before the reset's tick
    assert m.target_text(2) == "1.57"
    assert "world 1 reset" in m.status_text()


def test_failed_command_notices_clear_only_when_about_the_connection() -> None:
    m = ControllerModel(URL, 1)
    m.apply(Notice("Up failed: HTTP 422: bad joint"))
    m.apply(ConnectionStatus(True, "ws://x"))
    assert "Up failed: HTTP 422" in m.status_text()
    m.apply(Notice("Up failed: server unreachable", until_connected=True))
    assert "server unreachable" in m.status_text()
    m.apply(ConnectionStatus(True, "ws://x"))
    assert "failed" not in m.status_text()
