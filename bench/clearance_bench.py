"""Section 33: what the protective stop's watches cost beside the physics they guard.

The watch (service/core/commands/clearance_watch.py) measures every world whose arm targets
changed against the scene's fixed obstacles after every tick. Three figures, all CPU time of
this process (`time.process_time`: robust to other work on a shared box, unlike wall time):

- `Clearance.depth` for n worlds whose targets all changed at once, per world;
- the physics of one control tick of one world (native `mj_step` x the substeps of a tick), the
  yardstick: the watch's share of a tick is the first over the second;
- the watch's own rule (`due`) on n worlds following the bench's trajectory (section 21's
  swing, ±0.3 rad around home, every world at its own phase) at the control rate: how many
  worlds it measures a tick, and the CPU of its tick.

The torque watch (service/core/commands/torque_watch.py) judges every published snapshot: its
CPU per check of n native worlds at rest (the common case: no joint at its limit, one
comparison of the batch) and with every world's arm at its limit and still (the worst case:
every world counting its hold), beside one native tick of the same n worlds.

`armfleet bench --section 33` (off by default: seconds, on the CPU only).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import mujoco
import numpy as np

from bench import common
from bench.registry import Context, Result, section
from service.core.commands.clearance_watch import due
from service.core.commands.control import Control
from service.core.commands.torque_watch import TorqueWatch
from service.core.kinematics.clearance import Clearance
from service.core.kinematics.ur import URKinematics
from service.core.sim.loop import SimLoop
from service.core.sim.physics import tick_timing
from service.core.sim.robot import load_robot
from service.engines.native import NativeBatch

SWING = 0.3  # rad, section 21's "move" trajectory
SIGN = np.array([1.0, -0.7, 0.7, 1.0, -1.0, 1.0])
PERIOD_S = 4.0  # a swing there and back (section 21: 2 s between its points)


def _cpu(fn: Any, repeat: int) -> float:
    fn()  # warm
    t0 = time.process_time()
    for _ in range(repeat):
        fn()
    return (time.process_time() - t0) / repeat


def measure(n: int, ticks: int) -> dict[str, Any]:
    robot = load_robot()
    arm = robot.spec.names[:6]
    kin = URKinematics.from_model(robot.mjm, arm)
    clearance = Clearance.of_model(robot.mjm, arm, kin, robot.spec.names[6])
    assert clearance is not None
    home = np.asarray(robot.spec.home[:6], np.float64)
    rng = np.random.default_rng(0)
    q = home + rng.uniform(-SWING, SWING, (n, 6))
    opening = rng.uniform(0.0, 0.7, n)
    all_s = _cpu(lambda: clearance.depth(q, opening), max(3, 4096 // n))
    substeps, _ = tick_timing(common.CONTROL_HZ, common.PHYSICS_DT)
    data = mujoco.MjData(robot.mjm)
    mujoco.mj_resetDataKeyframe(robot.mjm, data, 0)
    step_s = _cpu(lambda: mujoco.mj_step(robot.mjm, data), 2000)
    # the watch's rule on the swing, at the control rate
    phase = rng.uniform(0.0, PERIOD_S, n)
    last, depth = np.full((n, 6), np.nan), np.full(n, -np.inf)
    last_opening, still = np.zeros(n), np.zeros(n)
    measured, cpu = 0, 0.0
    for k in range(ticks):
        t = k / common.CONTROL_HZ + phase
        target = home + SWING * SIGN * np.sin(2 * np.pi * t / PERIOD_S)[:, None]
        t0 = time.process_time()
        m = np.flatnonzero(due(clearance, target, still, last, last_opening, depth))
        if m.size:
            depth[m] = clearance.depth(target[m], still[m])[0]
            last[m] = target[m]
        cpu += time.process_time() - t0
        measured += m.size
    return {
        "worlds": n,
        "obstacles": list(clearance.obstacle_names),
        "arm_points": len(clearance.radius),
        "depth_all_ms": round(all_s * 1e3, 3),
        "depth_us_per_world": round(all_s / n * 1e6, 2),
        "physics_us_per_world_tick": round(step_s * substeps * 1e6, 1),
        "share_of_physics": round(all_s / (step_s * substeps * n), 4),
        "swing_measured_per_tick": round(measured / ticks, 1),
        "swing_ms_per_tick": round(cpu / ticks * 1e3, 3),
        "swing_deepest_mm": round(float(depth.max()) * 1e3, 1),
    }


def measure_torque(n: int, repeat: int) -> dict[str, Any]:
    """The torque watch's CPU per check of n native worlds: at rest, and every arm at its
    limit and still (the same snapshot again: every world counts, none reaches its hold)."""
    batch = NativeBatch(n)
    try:
        loop = SimLoop(batch)  # not started: the watch reads its safety table and spec only
        watch = TorqueWatch(Control(loop), [j.effort_limit for j in batch.spec.joints], 1 / 60)
        for _ in range(3):
            batch.step(1)
        rest = loop.listeners.extend(batch.snapshot(), batch)
        rest_s = _cpu(lambda: watch.publish(rest), repeat)
        effort = np.array(rest.effort)
        effort[:, :6] = watch.limits
        velocity = np.zeros_like(rest.velocity)
        pressed = dataclasses.replace(rest, effort=effort, velocity=velocity)
        pressed_s = _cpu(lambda: watch.publish(pressed), repeat)
        tick_s = _cpu(lambda: batch.step(1), max(3, repeat // 20))
    finally:
        batch.close()
    return {
        "rest_us": round(rest_s * 1e6, 1),
        "pressed_us": round(pressed_s * 1e6, 1),
        "tick_ms": round(tick_s * 1e3, 3),
        "stops": watch.control.loop.safety.modes().tolist().count(3),
    }


@section(33, "clearance", default_on=())
def clearance(ctx: Context) -> Result:
    """Safety watches: clearance and torque, CPU per check of n worlds vs their physics"""
    sizes = ctx.sizes((1024, 4096), quick=(256, 1024))
    ticks = ctx.pick(600, 120)
    rows, results, errors = [], {}, {}
    for n in sizes:
        try:
            r = results[str(n)] = measure(n, ticks)
        except Exception as exc:  # one failure loses one row
            errors[str(n)] = f"{type(exc).__name__}: {exc}"
            continue
        ctx.say(f"  {n} worlds: {r['depth_us_per_world']} us/world, swing {r['swing_ms_per_tick']}")
        rows.append(
            {
                "measure": f"{n} worlds, every target changed: Clearance.depth",
                "value": f"{r['depth_all_ms']} ms CPU ({r['depth_us_per_world']} µs/world)",
                "ratio": f"{r['share_of_physics']} of the tick's physics",
            }
        )
        t = r["torque"] = measure_torque(n, ctx.pick(2000, 200))
        ctx.say(f"  {n} worlds: torque watch {t['rest_us']} / {t['pressed_us']} us a check")
        rows.append(
            {
                "measure": f"{n} native worlds: torque watch, a check (at rest / all pressed)",
                "value": f"{t['rest_us']} / {t['pressed_us']} µs CPU",
                "ratio": f"a native tick: {t['tick_ms']} ms CPU",
            }
        )
        rows.append(
            {
                "measure": f"{n} worlds swinging ±{SWING} rad at {common.CONTROL_HZ:g} Hz",
                "value": f"{r['swing_measured_per_tick']} measured a tick, "
                f"{r['swing_ms_per_tick']} ms CPU a tick",
                "ratio": "",
            }
        )
    return Result.per_size(
        rows,
        results,
        errors,
        notes=["CPU time of this process; physics: native mj_step x the substeps of a tick"],
    )
