"""The controllers' view model without widgets or network: what the rows and status show."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import HOME, JOINTS

from clients import CommandAck, ConnectionStatus, Info, JointInfo, ResetResult, WorldState
from clients.apps.controller import ControllerModel, Notice
from clients.apps.jog import STEPS, JogPad, button_text, step_texts
from clients.cartesian import AXES
from service.core.commands.cartesian import JOG_STEP

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
    # the cursor runs over the seven joint rows, then the six jog rows, and wraps around
    assert m.move_selection(-1) == 12 and m.selected_joint() is None
    assert m.selected_axis() == "rz"
    assert m.move_selection(-6) == 6 and m.selected_joint() == JOINTS[6]
    assert m.selected_axis() is None
    assert m.move_selection(1) == 7 and m.selected_axis() == "x"
    assert m.move_selection(6) == 0 and m.selected_joint() == JOINTS[0]


def test_jog_pad_starts_at_a_centimetre_in_the_base_frame() -> None:
    pad = ControllerModel(URL, 0).jog
    assert pad.frame == "base"
    assert [pad.step(a, 1) for a in AXES] == [0.01, 0.01, 0.01, 0.05, 0.05, 0.05]
    assert pad.step("z", -1) == -0.01 and pad.step("rx", -1) == -0.05
    assert [button_text(a, s) for a in ("y", "ry") for s in (-1, 1)] == ["-Y", "+Y", "-Ry", "+Ry"]
    assert pad.summary() == "Jog: base frame, step 10 mm / 0.05 rad"
    assert pad.row_label("z") == "jog Z [m]" and pad.row_label("rx") == "jog Rx [rad]"
    assert pad.row_step_text("x") == "±0.01" and pad.row_step_text("rz") == "±0.05"


def test_jog_pad_frame_switch_and_step_presets() -> None:
    pad = JogPad()
    assert pad.toggle_frame() == "tool" and pad.toggle_frame() == "base"
    pad.set_frame("tool")
    assert pad.frame == "tool"
    with pytest.raises(ValueError, match="frame"):
        pad.set_frame("world")
    with pytest.raises(ValueError, match="axis"):
        pad.step("w", 1)
    assert step_texts() == ["1 mm / 0.01 rad", "10 mm / 0.05 rad", "50 mm / 0.1 rad"]
    assert pad.cycle_step() == 2 and pad.step("x", 1) == 0.05 and pad.step("rz", 1) == 0.1
    assert pad.cycle_step() == 0 and pad.step("y", -1) == -0.001
    assert pad.cycle_step(-1) == 2
    pad.set_step_text("1 mm / 0.01 rad")
    assert pad.step("ry", 1) == 0.01
    # every preset is a step the server takes (it refuses more than JOG_STEP per press)
    assert all(0 < size <= JOG_STEP for preset in STEPS for size in preset)


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
