"""ur_rtde's control script, carried out natively for one world (no URScript interpreter).

The uploaded program is recognised (control_script.py); from then on this runner does what its
main loop does, driven by the world's RTDE input registers (each input package the client
sends) and a timer: it reads the command number (input integer register 0 + offset), decodes
its arguments (script_commands.py), carries it out through `Motion` (the core's commands), and
writes the output registers the client waits on, exactly as the script's `signal_ready()`
(output integer register 0 = 1), `signal_done_with_cmd()` (= 2) and
`write_async_progress_register()` (register 2: running bit, progress, counters) do. A blocking
command (a synchronous move or stop) holds the loop until its trajectory ends, as
`process_cmd` does on the robot; realtime commands (servo, speed) answer ready at once.

While it runs, the world's program is PLAYING (RTDE robot_status_bits bit 1 and
runtime_state, the Dashboard's `running` and `programState`). It ends on stopScript, on the
Dashboard's stop, on a protective stop, or when a command cannot be carried out (refused, or a
value out of range): then the program is STOPPED with a line in the service log naming the
command, and ur_rtde's next call returns False, as with a robot whose script failed.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable
from typing import TYPE_CHECKING, Any

import numpy as np

from service.core.errors import BadCommand, ProtectiveStopped
from service.surfaces.ur import script_commands as sc
from service.surfaces.ur import urscript
from service.surfaces.ur.control_script import ControlScript
from service.surfaces.ur.controller import ProgramState
from service.surfaces.ur.motion import Motion
from service.surfaces.ur.speed import SpeedLoop

if TYPE_CHECKING:
    from service.surfaces.ur.world_robot import WorldRobot

log = logging.getLogger("armfleet.ur")
READY, DONE = 1, 2
PERIOD_S = 0.008  # the timer: speed integration and the program's liveness
SETTLED = 2e-4  # rad: a blocking move returns once every joint is this near its target
SETTLE_S = 1.0
STEADY = 2e-3  # rad/s: isSteady below this on every joint with no move running


def start_script(robot: WorldRobot, script: ControlScript) -> None:
    """ur_rtde's control script arrived: it replaces the running program, if it may run."""
    robot.end_script("a new program replaced it")
    robot.end_speed_loop()
    ctl = robot.controller
    if not ctl.can_run_script():
        log.warning(
            "world %d: control script not started: robot mode %s, safety mode %s",
            robot.world, ctl.robot_mode.name, ctl.safety_mode.name,
        )  # fmt: skip
        robot.log_message("program not started: the robot is not ready (mode, safety)")
        return
    runner = ScriptRunner(robot, script, robot.motion)
    robot.runner = runner
    runner.start()


class ScriptRunner:
    """One world's running control script (see the module docstring)."""

    def __init__(self, robot: WorldRobot, script: ControlScript, motion: Motion) -> None:
        self.robot, self.script, self.motion = robot, script, motion
        self.world, self.ctl = robot.world, robot.controller
        self.off = script.register_offset
        self.executing = False
        self.busy = False
        self.alive = False
        self._async_task: asyncio.Task[None] | None = None
        self._busy_task: asyncio.Task[None] | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._count = self._op = 0
        self.speed = SpeedLoop(motion, robot.world)

    # -- life -------------------------------------------------------------------------------

    def start(self) -> None:
        self.alive = True
        self.ctl.set_program(ProgramState.PLAYING)
        self._async(-1)
        self._out_int(0, READY)
        log.info(
            "world %d: ur_rtde control script %s (%s, register offset %d) running natively",
            self.world, self.script.banner, self.script.versions, self.off,
        )  # fmt: skip
        self._timer = asyncio.get_running_loop().call_later(PERIOD_S, self._tick)

    def end(self, why: str, halt: bool = True) -> None:
        """The program ends: motion it started stops, the program is STOPPED."""
        if not self.alive:
            return
        self.alive = False
        for task in (self._async_task, self._busy_task):
            if task is not None:
                task.cancel()
        if self._timer is not None:
            self._timer.cancel()
        was_moving = self.speed.active or self.busy or self._async_task is not None
        self.speed.end()
        if halt and was_moving:
            self.motion.halt(self.world)
        if self.ctl.program is ProgramState.PLAYING:
            self.ctl.set_program(ProgramState.STOPPED)
        log.info("world %d: control script ended: %s", self.world, why)

    def _fail(self, why: str) -> None:
        log.warning("world %d: control script stopped: %s", self.world, why)
        self.end(why)

    def _tick(self) -> None:
        if not self.alive:
            return
        if self.ctl.program is not ProgramState.PLAYING:
            return self.end("the program was stopped (Dashboard)")
        try:
            self.speed.step(PERIOD_S)
        except (BadCommand, ProtectiveStopped) as exc:
            return self._fail(f"speed: {exc}")
        self._timer = asyncio.get_running_loop().call_later(PERIOD_S, self._tick)

    # -- registers --------------------------------------------------------------------------

    def _out_int(self, i: int, value: int) -> None:
        self.ctl.output_int[i + self.off] = int(value)
        self.ctl.changed()

    def _out_doubles(self, values: Any) -> None:
        for i, v in enumerate(values):
            self.ctl.output_double[i + self.off] = float(v)
        self.ctl.changed()

    def _async(self, value: int) -> None:
        """write_async_progress_register(value): 0 started, >0 progress, <0 finished."""
        self._count = 0 if self._count >= 127 else self._count + 1
        if value == 0:
            self._op = 0 if self._op >= 127 else self._op + 1
        reg = self._count * 65536 + self._op * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self._out_int(2, reg)

    # -- the main loop ----------------------------------------------------------------------

    def on_inputs(self) -> None:
        """An input package arrived: one pass of the script's main loop."""
        if not self.alive or self.busy:
            return
        regs = sc.Registers(self.ctl.inputs, self.off)
        cmd = regs.n(0)
        if cmd in sc.REALTIME:
            self._process(cmd, regs)
            if self.alive:
                self._out_int(0, READY)
        elif cmd == 0:
            self.executing = False
            self._out_int(0, READY)
        elif not self.executing:
            self.executing = True
            self._process(cmd, regs)

    def _process(self, number: int, regs: sc.Registers) -> None:
        try:
            cmd = sc.decode(number, regs)
            pending = self._carry_out(cmd)
        except (sc.BadRegister, BadCommand, ProtectiveStopped) as exc:
            return self._fail(str(exc))
        if not self.alive:
            return
        if pending is None:
            self._out_int(0, DONE)
            return
        self.busy = True
        self._busy_task = asyncio.ensure_future(self._finish(cmd.name, pending))

    async def _finish(self, name: str, pending: Awaitable[Any]) -> None:
        try:
            await pending
            await self._settle()
        except (sc.BadRegister, BadCommand, ProtectiveStopped, urscript.ScriptError) as exc:
            return self._fail(f"{name}: {exc}")
        finally:
            self.busy = False
        if self.alive:
            self._out_int(0, DONE)

    # -- the commands -----------------------------------------------------------------------

    def _carry_out(self, cmd: sc.ScriptCommand) -> Awaitable[Any] | None:
        a, m, w = cmd.args, self.motion, self.world
        name = cmd.name
        if name in ("moveJ", "moveJ_IK", "moveL", "moveL_FK"):
            return self._move(name, a)
        if name == "movePath":
            return self._start(self._path(), a["async"])
        if name in ("servoJ", "servoL"):
            q = np.array(a["q"]) if name == "servoJ" else self._ik(a["pose"], m.targets(w))
            self.speed.end()
            m.servo(w, q)
        elif name in ("speedJ", "speedL"):
            self._stop_async()
            self.speed.begin("joint" if name == "speedJ" else "tool", a["speed"], a["accel"])
        elif name == "jogStart":
            self._stop_async()
            self.speed.jog(a["speed"], a["feature"], a["accel"], a["frame"])
        elif name in ("speedStop", "servoStop", "jogStop", "stopL", "stopJ"):
            self._stop_async()
            self.speed.end()
            started = m.stop(w, a.get("decel", 1.2))
            if started is not None and not a.get("async", False):
                return asyncio.wrap_future(m.wait(started))
        elif name == "setPayload":
            m.set_payload(w, a["mass"], a["cog"])
        elif name == "setTcp":
            m.set_tcp(w, a["pose"])
        elif name == "getTCPOffset":
            self._out_doubles(m.tcp(w))
        elif name == "getStepTime":
            self._out_doubles([0.002])
        elif name == "getForwardKinematics":
            q = np.array(a["q"]) if "q" in a else m.actual(w)[0]
            self._out_doubles(m.fk(q, np.array(a["tcp"]) if "tcp" in a else m.tcp(w)))
        elif name == "getActualToolFlangePose":
            self._out_doubles(m.fk(m.actual(w)[0], np.zeros(6)))
        elif name == "getInverseKinematics":
            self._out_doubles(self._ik(a["pose"], np.array(a.get("q_near", m.actual(w)[0]))))
        elif name in ("getInverseKinematicsHasSolution", "isPoseWithinSafetyLimits"):
            near = np.array(a.get("q_near", m.actual(w)[0]))
            self._out_int(1, int(m.ik(np.array(a["pose"]), near, m.tcp(w)) is not None))
        elif name == "isJointsWithinSafetyLimits":
            q = np.array(a["q"])
            self._out_int(1, int(bool(((q >= m.lower) & (q <= m.upper)).all())))
        elif name == "getJointTorques":
            frame = m._frame()
            effort = frame.snap.effort[w, :6] if frame is not None else np.zeros(6)
            self._out_doubles(effort)
        elif name == "isSteady":
            qd = m.actual(w)[1]
            moving = m.running(w) is not None or self.speed.active
            self._out_int(1, int(not moving and float(np.abs(qd).max()) < STEADY))
        elif name == "triggerProtectiveStop":
            self.robot.protective_stop("triggered by the program (triggerProtectiveStop)")
        elif name == "stopScript":
            self.end("stopScript (command 255)")
        return None

    async def _settle(self) -> None:
        """After a blocking move's trajectory: until the arm is at its targets (a UR's move
        returns with the arm there; the servos here lag a few milliradians), 1 s at most."""
        m, w = self.motion, self.world
        for _ in range(round(SETTLE_S / PERIOD_S)):
            q, qd = m.actual(w)
            if np.abs(q - m.targets(w)).max() < SETTLED and np.abs(qd).max() < STEADY * 10:
                return
            await asyncio.sleep(PERIOD_S)

    def _ik(self, pose: list[float], near: np.ndarray) -> np.ndarray:
        q = self.motion.ik(np.array(pose), near, self.motion.tcp(self.world))
        if q is None:
            raise sc.BadRegister(f"get_inverse_kin: no joint configuration reaches {pose}")
        return q

    def _move(self, name: str, a: dict[str, Any]) -> Awaitable[Any] | None:
        m, w = self.motion, self.world
        self._stop_async()
        self.speed.end()
        if name == "moveJ_IK":
            a = {**a, "q": self._ik(a["pose"], m.targets(w)).tolist()}
        if name == "moveL_FK":
            a = {**a, "pose": m.fk(np.array(a["q"]), m.tcp(w)).tolist()}
        if name in ("moveJ", "moveJ_IK"):
            started = m.move_joints(w, np.array(a["q"]), a["speed"], a["accel"])
        else:
            started = m.move_linear(w, np.array(a["pose"]), a["speed"], a["accel"])
        return self._start(asyncio.wrap_future(m.wait(started)), a["async"])

    def _start(self, move: Awaitable[Any], is_async: bool) -> Awaitable[Any] | None:
        """A blocking move, or one run in the background with the async progress register."""
        if not is_async:
            return move

        async def background() -> None:
            self._async(0)
            try:
                await move
            except (sc.BadRegister, BadCommand, ProtectiveStopped, urscript.ScriptError) as exc:
                self._fail(str(exc))
            finally:
                if self.alive:
                    self._async(-1)
                self._async_task = None

        self._async_task = asyncio.ensure_future(background())
        return None

    def _stop_async(self) -> None:
        """stop_async_move(): a move running in the background is killed (finished)."""
        task = self._async_task
        if task is not None:
            task.cancel()
            self._async_task = None
            self._async(-1)

    async def _path(self) -> None:
        """exec_move_path(): the moves ur_rtde injected, one after the other."""
        m, w = self.motion, self.world
        for call in self.script.path:
            args = urscript.bind(call)
            if call.name == "signal_async_progress":
                self._async(int(args["i"]))
                continue
            if call.name == "movej":
                q = args["q"]
                if args["is_pose"]:
                    q = self._ik(q, m.targets(w)).tolist()
                started = m.move_joints(w, np.array(q), args["v"], args["a"])
            else:
                pose = args["pose"]
                if not args["is_pose"]:
                    pose = m.fk(np.array(pose), m.tcp(w)).tolist()
                started = m.move_linear(w, np.array(pose), args["v"], args["a"])
            await asyncio.wrap_future(m.wait(started))
