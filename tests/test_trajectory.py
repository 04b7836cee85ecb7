"""Trajectories in the loop: validation, interpolation, tracking on both engines, outcomes.

The loop runs paused and is stepped tick by tick, so every check is on simulated time; the
engines are real (MuJoCo Warp on the CPU and native MuJoCo), nothing is mocked.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from service.core.commands.control import Control
from service.core.commands.trajectory import (
    MAX_DURATION_S,
    MAX_POINTS,
    AbortReason,
    JointTolerance,
    JointTrajectorySpec,
    TrajectoryPoint,
    TrajectoryState,
    parse,
)
from service.core.commands.trajectory.table import TrajectoryTable
from service.core.errors import BadCommand
from service.core.sim.loop import SimLoop
from service.core.sim.settings import SimSettings
from service.core.sim.types import Mode
from service.engines.choice import build_batch
from service.engines.settings import EngineSettings
from tests.conftest import HOME, JOINTS, SPEC

ARM = JOINTS[:6]
HOME6 = np.array(HOME[:6])
# Three points of a 2 s move of all six arm joints, clear of the table and of the arm itself.
WAYPOINTS = [
    (0.7, HOME6 + [0.5, -0.3, 0.3, 0.3, -0.4, 0.6]),
    (1.4, HOME6 + [0.9, -0.5, 0.6, -0.2, 0.3, 1.2]),
    (2.0, HOME6 + [0.4, -0.2, 0.2, 0.3, 0.5, 0.3]),
]


def three_points(velocities: bool = True, **kw: object) -> JointTrajectorySpec:
    """WAYPOINTS; with velocities (cubic) from the neighbours' slopes, zero at the end."""
    times = [0.0] + [t for t, _ in WAYPOINTS]
    pos = [HOME6] + [p for _, p in WAYPOINTS]
    points = []
    for i in range(1, 4):
        vel = (pos[min(i + 1, 3)] - pos[i - 1]) / (times[min(i + 1, 3)] - times[i - 1])
        vel = vel if i < 3 else np.zeros(6)
        points.append(TrajectoryPoint(list(pos[i]), times[i], list(vel) if velocities else ()))
    return JointTrajectorySpec.build(SPEC, ARM, points, **kw)  # type: ignore[arg-type]


def stepped(ticks: int, loop: SimLoop) -> None:
    loop.step(ticks).result(timeout=60)


@pytest.fixture(scope="module", params=["warp", "mujoco"])
def engine(request: pytest.FixtureRequest) -> Iterator[tuple[SimLoop, Control]]:
    # the engine `serve --engine X --shards 1` runs: one process, one thread
    batch = build_batch(EngineSettings(kind=request.param, shards=1), SimSettings(worlds=4))
    loop = SimLoop(batch, Mode.PAUSED)
    control = Control(loop)
    loop.start()
    yield loop, control
    loop.stop()
    batch.close()


@pytest.fixture
def sim(engine: tuple[SimLoop, Control]) -> tuple[SimLoop, Control]:
    loop, control = engine
    control.reset(None, "http")
    stepped(1, loop)
    return engine


# -- validation: before anything changes ---------------------------------------------------


def _body(**over: object) -> dict:
    body = {
        "joint_names": ["shoulder_pan_joint", "elbow_joint"],
        "points": [
            {"positions": [0.1, 1.0], "time_from_start": 0.5},
            {"positions": [0.2, 1.2], "time_from_start": {"sec": 1, "nanosec": 0}},
        ],
    }
    body.update(over)
    return body


def _pts(*rows: dict) -> list[dict]:
    return list(rows)


@pytest.mark.parametrize(
    ("body", "field", "words"),
    [
        (_body(joint_names=["shoulder_pan_joint", "nope"]), "joint_names[1]", "unknown joint"),
        (_body(joint_names=["elbow_joint", "elbow_joint"]), "joint_names[1]", "named twice"),
        (_body(joint_names=[]), "joint_names", "at least one"),
        (_body(points=[]), "points", "at least one point"),
        (
            _body(points=_pts({"positions": [0.1], "time_from_start": 1})),
            "points[0].positions",
            "has 1 values; joint_names has 2",
        ),
        (
            _body(points=_pts({"positions": [0.1, float("nan")], "time_from_start": 1})),
            "points[0].positions[1]",
            "finite",
        ),
        (
            _body(points=_pts({"positions": [0.1, 9.0], "time_from_start": 1})),
            "points[0].positions[1]",
            "outside elbow_joint's limits",
        ),
        (
            _body(
                points=_pts(
                    {"positions": [0.1, 1], "time_from_start": 1},
                    {"positions": [0.1, 1], "time_from_start": 1},
                )
            ),
            "points[1].time_from_start",
            "times must increase",
        ),
        (
            _body(points=_pts({"positions": [0.1, 1], "time_from_start": -1})),
            "points[0].time_from_start",
            ">= 0",
        ),
        (
            _body(points=_pts({"positions": [0.1, 1], "time_from_start": MAX_DURATION_S + 1})),
            "points[0].time_from_start",
            f"limit of {MAX_DURATION_S:g} s",
        ),
        (
            _body(
                points=[
                    {"positions": [0.1, 1], "time_from_start": 0.01 * (i + 1)}
                    for i in range(MAX_POINTS + 1)
                ]
            ),
            "points",
            f"at most {MAX_POINTS}",
        ),
        (
            _body(
                points=_pts(
                    {"positions": [0.1, 1], "velocities": [0, 0], "time_from_start": 1},
                    {"positions": [0.1, 1], "time_from_start": 2},
                )
            ),
            "points[1].velocities",
            "every point or none",
        ),
        (
            _body(path_tolerance=[{"name": "wrist_1_joint", "position": 0.1}]),
            "path_tolerance[0].name",
            "not in joint_names",
        ),
        (_body(goal_time_tolerance=float("inf")), "goal_time_tolerance", "finite"),
    ],
)
def test_bad_trajectories_are_rejected_naming_the_field_and_limit(body, field, words):
    with pytest.raises(BadCommand) as err:
        parse(SPEC, body)
    assert err.value.field == field
    assert words in err.value.message


def test_a_rejected_trajectory_changes_nothing(sim):
    loop, control = sim
    before = loop.commands.pending_targets(np.arange(4))
    with pytest.raises(BadCommand):
        parse(SPEC, _body(joint_names=["nope"]))
    assert control.trajectories.status(0) is None or control.trajectories.status(0).done
    np.testing.assert_array_equal(loop.commands.pending_targets(np.arange(4)), before)


def test_spec_round_trips_through_json():
    spec = three_points(
        path_tolerance=[JointTolerance("elbow_joint", position=0.1)], goal_time_tolerance=0.5
    )
    again = parse(SPEC, spec.to_json())
    for name in ("times", "positions", "velocities", "path_position", "goal_position"):
        np.testing.assert_array_equal(getattr(again, name), getattr(spec, name))
    assert again.goal_time_tolerance == 0.5 and again.order == 3


# -- interpolation: ros2_controllers' three kinds -------------------------------------------


@pytest.mark.parametrize("kind", ["linear", "cubic", "quintic"])
def test_the_table_passes_through_every_point_with_its_velocity(kind):
    dt = 0.01
    table = TrajectoryTable(dt)
    times = [0.3, 0.6, 1.0]
    pos = [[0.2], [0.5], [0.1]]
    vel = [[1.0], [-0.5], [0.0]] if kind != "linear" else None
    acc = [[0.0], [2.0], [0.0]] if kind == "quintic" else None
    points = [
        TrajectoryPoint(pos[i], t, vel[i] if vel else (), acc[i] if acc else ())
        for i, t in enumerate(times)
    ]
    spec = JointTrajectorySpec.build(SPEC, ["elbow_joint"], points)
    start = SPEC.home.copy()
    end = table.add(np.array([1]), np.array([0]), spec, 1, start[None], np.zeros((1, 7)))
    assert end == 100  # sampled at the end of each tick: tick 100 ends at t = 1.0 s
    samples = {k: table.sample(k) for k in range(1, 101)}
    e = SPEC.index("elbow_joint")
    for i, t in enumerate(times):
        s = samples[round(t / dt)]
        assert s.positions[0, e] == pytest.approx(pos[i][0], abs=1e-9)
        if vel and i < 2:
            assert s.velocities[0, e] == pytest.approx(vel[i][0], abs=1e-9)
        if acc and i < 2:
            assert s.accelerations[0, e] == pytest.approx(acc[i][0], abs=1e-6)
    # The other joints hold their start target with no feed-forward; the end holds exactly.
    others = [j for j in range(7) if j != e]
    np.testing.assert_array_equal(samples[50].positions[0, others], start[others])
    assert not samples[50].velocities[0, others].any()
    assert samples[100].ended[0] and not samples[99].ended[0]
    assert samples[100].positions[0, e] == 0.1 and samples[100].velocities[0, e] == 0.0
    if kind == "linear":  # constant slope on a segment: (0.5 - 0.2) / 0.3 s
        assert samples[45].velocities[0, e] == pytest.approx(1.0)


# -- tracking on both engines -----------------------------------------------------------------


def test_a_2s_three_point_trajectory_tracks_within_0_03_rad_and_settles(sim):
    loop, control = sim
    hz = loop.batch.control_hz
    started = control.start_trajectory([1], three_points(), "http")[0]
    assert started.end_tick - started.start_tick + 1 == round(2.0 * hz)
    worst = 0.0
    while loop.tick < started.end_tick:
        stepped(1, loop)
        status = control.trajectories.status(1)
        if status.feedback_tick == loop.tick:
            worst = max(worst, float(np.abs(status.error).max()))
    final = control.trajectories.status(1)
    assert final.state is TrajectoryState.SUCCEEDED and final.finished_tick == started.end_tick
    assert final.progress == 1.0
    stepped(round(0.5 * hz), loop)
    snap = loop.latest
    # the trajectories guide: "tracks within 0.03 rad and ends within 0.0002 rad of its last
    # point 0.5 s after its end, on both engines"
    np.testing.assert_allclose(snap.position[1, :6], WAYPOINTS[-1][1], atol=2e-4)
    np.testing.assert_array_equal(snap.target[1, :6], WAYPOINTS[-1][1])  # held exactly
    assert 0 < worst <= 0.03, f"largest path error {worst:.4f} rad"
    # The other worlds never moved their targets.
    np.testing.assert_array_equal(snap.target[[0, 2, 3]], np.tile(HOME, (3, 1)))


# -- outcomes ---------------------------------------------------------------------------------


def test_manual_command_stops_the_trajectory_and_holds(sim):
    loop, control = sim
    started = control.start_trajectory([0], three_points(), "http")[0]
    stepped(30, loop)
    outcome = control.trajectories.wait(started.id)
    held = loop.commands.pending_targets(0)
    result = control.increment(0, {"elbow_joint": 0.1}, "browser")
    assert outcome.done()  # told at once, though no tick has run since (paused)
    status = control.trajectories.status(0)
    assert status.state is TrajectoryState.ABORTED
    assert status.reason is AbortReason.MANUAL_OVERRIDE
    want = held.copy()
    want[2] = round(want[2] + 0.1, 9)
    np.testing.assert_allclose(result.target, want)
    stepped(5, loop)
    np.testing.assert_allclose(loop.latest.target[0], want)  # not moved on by the trajectory


def test_takeover_is_joint_scoped_a_gripper_command_leaves_the_arm_running(sim):
    """The arm and the gripper are separate controllers, as on a UR with a Robotiq: a finger
    command (even staged between the same two ticks as a trajectory sample) moves the finger
    and the arm trajectory goes on; a target on one of the trajectory's joints takes over."""
    loop, control = sim
    arm = control.start_trajectory([0], three_points(), "http")[0]
    elbow = JointTrajectorySpec.build(SPEC, ["elbow_joint"], [TrajectoryPoint([1.0], 0.5)])
    part = control.start_trajectory([1], elbow, "http")[0]
    stepped(10, loop)
    finger = control.command_targets(0, ["finger_joint"], [0.5], "ros2")
    pan = control.increment(1, {"shoulder_pan_joint": 0.2}, "browser")
    assert control.trajectories.status(0).state is TrajectoryState.RUNNING
    assert control.trajectories.status(1).state is TrajectoryState.RUNNING
    stepped(1, loop)
    assert loop.latest.target[0, 6] == finger.target[6] == 0.5  # not written over by the sample
    assert loop.latest.target[1, 0] == pan.target[0]
    assert loop.latest.target[1, 2] != pan.target[2]  # the elbow follows its trajectory
    stepped(arm.end_tick - loop.tick, loop)
    assert control.trajectories.get(arm.id).state is TrajectoryState.SUCCEEDED
    assert control.trajectories.get(part.id).state is TrajectoryState.SUCCEEDED
    snap = loop.latest
    np.testing.assert_array_equal(snap.target[0, :6], WAYPOINTS[-1][1])
    assert snap.target[0, 6] == 0.5 and snap.position[0, 6] > 0.3  # the finger closed
    # A target on one of the trajectory's joints (and a batch row: every joint) takes over.
    for command in (
        lambda: control.command_targets(2, ["finger_joint", "wrist_3_joint"], [0, 0], "ws"),
        lambda: control.set_many([2], [HOME], "http"),
    ):
        control.start_trajectory([2], three_points(), "http")
        stepped(5, loop)
        command()
        assert control.trajectories.status(2).reason is AbortReason.MANUAL_OVERRIDE


def test_a_newer_trajectory_preempts_and_starts_where_the_old_one_was(sim):
    loop, control = sim
    first = control.start_trajectory([0], three_points(), "http")[0]
    stepped(20, loop)
    where = loop.commands.pending_targets(0)
    hold = JointTrajectorySpec.build(
        SPEC, ["elbow_joint"], [TrajectoryPoint([float(where[2])], 0.5)]
    )
    second = control.start_trajectory([0], hold, "ws")[0]
    assert control.trajectories.get(first.id).reason is AbortReason.PREEMPTED
    stepped(1, loop)
    # Joints outside the new trajectory keep the target they had; elbow starts from it.
    np.testing.assert_array_equal(loop.latest.target[0, :2], where[:2])
    assert abs(loop.latest.target[0, 2] - where[2]) < 1e-9
    stepped(second.end_tick - loop.tick, loop)
    assert control.trajectories.get(second.id).state is TrajectoryState.SUCCEEDED


def test_cancel_reset_and_fault_abort_with_their_reason(sim):
    loop, control = sim
    control.start_trajectory([0, 1, 2], three_points(), "http")
    stepped(10, loop)
    stopped = control.cancel_trajectory([0, 3], "http")
    assert [s.world for s in stopped] == [0]  # world 3 ran none: nothing to cancel
    control.reset([1], "http")
    qpos = loop.batch.qpos()[2]
    qpos[0] = np.nan
    loop.call(lambda b: b.write_qpos(2, qpos)).result()
    stepped(2, loop)
    reasons = {w: control.trajectories.status(w).reason for w in (0, 1, 2)}
    assert reasons == {0: AbortReason.CANCELLED, 1: AbortReason.RESET, 2: AbortReason.FAULT}
    np.testing.assert_array_equal(loop.latest.target[[1, 2]], np.tile(HOME, (2, 1)))
    assert not len(control.trajectories.table)


def test_path_tolerance_aborts_naming_the_joint(sim):
    loop, control = sim
    tight = [JointTolerance("shoulder_pan_joint", position=1e-4)]
    started = control.start_trajectory([3], three_points(path_tolerance=tight), "http")[0]
    done = control.trajectories.wait(started.id)
    stepped(30, loop)
    status = done.result(timeout=5)
    assert status.reason is AbortReason.PATH_TOLERANCE
    assert "shoulder_pan_joint" in status.detail and status.finished_tick < 30 + started.start_tick


def test_goal_tolerance_waits_for_the_goal_then_succeeds(sim):
    loop, control = sim
    goal = [JointTolerance(n, position=0.002) for n in ARM]
    started = control.start_trajectory(
        [2], three_points(goal_tolerance=goal, goal_time_tolerance=1.0), "http"
    )[0]
    stepped(started.end_tick - loop.tick + round(1.0 * loop.batch.control_hz), loop)
    status = control.trajectories.get(started.id)
    assert status.state is TrajectoryState.SUCCEEDED
    assert started.end_tick <= status.finished_tick <= started.end_tick + 60


def test_many_worlds_start_at_one_tick(sim):
    loop, control = sim
    started = control.start_trajectory([0, 1, 2, 3], three_points(), "http")
    assert len({(s.start_tick, s.end_tick) for s in started}) == 1
    assert len({s.id for s in started}) == 4
    stepped(10, loop)
    targets = loop.latest.target
    np.testing.assert_array_equal(targets[0], targets[3])  # same plan, same tick
    assert not np.array_equal(targets[0], HOME)
