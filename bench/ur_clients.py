"""The clients of the UR section (bench/ur_programs.py): one ur_rtde program, and raw RTDE
receivers that count what they get.

Why two kinds. A program is what a user runs against a UR10e: the registry's ur-rtde 1.6.5
wheel, unchanged (`RTDEControlInterface` + `RTDEReceiveInterface`, their default 500 Hz
streams), in a process of its own, so that 32 of them are 32 programs as a user's test suite
would start them. The receivers count packages, which ur_rtde cannot: its API hands out the
latest values and no package count, and a timestamp that moves only at the service's ticks.
A raw client (handshake, one output recipe at 500 Hz, start) counts bytes of a fixed-size data
package, so 32 of them fit in one process of the bench for little CPU.

Nothing here is imported by the service; rtde_control is imported inside the child process.
"""

from __future__ import annotations

import contextlib
import os
import selectors
import socket
import struct
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NoReturn

RTDE_PORT = 30004
CALLS = ("moveJ", "moveL", "command", "read")  # what a program times
CLEANUP_S = 15.0  # stopScript and the disconnects, at most
PRINTED_LINES = 8  # of what ur_rtde printed, kept for a failed program
# What a receive program typically reads (ur_rtde's RTDEReceiveInterface asks for more): the
# package the receivers get at 500 Hz, 337 bytes with its header.
RECEIVE_RECIPE = (
    "timestamp,actual_q,actual_qd,actual_current,actual_TCP_pose,actual_TCP_speed,target_q,"
    "robot_mode,safety_mode,runtime_state,speed_scaling,output_int_register_0"
)


# -- one ur_rtde program (a child process) ------------------------------------------------------


def program(address: str, world: int, barrier: Any, out: Any) -> None:
    """A user's ur_rtde program on one world: connect, wait for the others (`barrier`), then
    moveJ, two moveL, command round trips (getForwardKinematics, isSteady), reads, moveJ
    back; `out.put` gets what happened and how long each call took, and what ur_rtde printed
    when the program failed. The process then ends at once (see `_finish`)."""
    res: dict[str, Any] = {"world": world, "address": address, "ok": False, "error": None}
    calls: dict[str, list[float]] = {k: [] for k in CALLS}
    res["calls"] = calls
    printed = _capture_output()
    c = r = None
    try:
        import rtde_control
        import rtde_receive

        t0 = time.perf_counter()
        c = rtde_control.RTDEControlInterface(address)
        r = rtde_receive.RTDEReceiveInterface(address)
        res["connect_s"] = time.perf_counter() - t0
    except Exception as exc:  # the run goes on: this program failed
        res["error"] = f"connect: {type(exc).__name__}: {exc}"
    try:
        barrier.wait(timeout=300)
    except Exception as exc:
        res["error"] = res["error"] or f"barrier: {type(exc).__name__}"
    if c is None or r is None or res["error"]:
        _finish(res, out, printed)
    started, cpu = time.perf_counter(), time.process_time()
    try:
        res["ok"] = _moves(c, r, calls, res)
    except Exception as exc:
        res["error"] = f"{type(exc).__name__}: {exc}"
    res["run_s"] = time.perf_counter() - started
    res["run_cpu_s"] = time.process_time() - cpu  # this process, all its threads
    res["cleanup"] = _cleanup(c, r)
    _finish(res, out, printed)


def _cleanup(c: Any, r: Any) -> str:
    """stopScript and both disconnects, in a thread given CLEANUP_S: 'done', or what hung.

    Why a thread: after a dropped connection ur_rtde 1.6.5's control interface may never
    recover (its receive thread reconnects again and again), and stopScript then waits on a
    program state that never comes; the bench records that and goes on."""
    step = ["stopScript"]

    def run() -> None:
        with contextlib.suppress(Exception):
            c.stopScript()
        step[0] = "disconnect"
        with contextlib.suppress(Exception):
            c.disconnect()
            r.disconnect()
        step[0] = "done"

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(CLEANUP_S)
    return step[0] if step[0] == "done" else f"{step[0]} hung ({CLEANUP_S:g} s)"


def _capture_output() -> Any:
    """What ur_rtde prints (std::cout and std::cerr, this process's fds 1 and 2) goes to a
    temporary file, read back for a failed program's result."""
    f = tempfile.TemporaryFile(mode="w+b")  # noqa: SIM115 (open until the process ends)
    for fd in (1, 2):
        os.dup2(f.fileno(), fd)
    return f


def _finish(res: dict[str, Any], out: Any, printed: Any) -> NoReturn:
    """Hand `res` over and end the process without its destructors: ur_rtde's join their
    receive threads, which a program that lost its connection may never end."""
    if not res["ok"]:
        printed.seek(0)
        lines = printed.read().decode(errors="replace").splitlines()
        res["ur_rtde_printed"] = {"lines": len(lines), "last": lines[-PRINTED_LINES:]}
    out.put(res)
    out.close()
    out.join_thread()  # the queue's feeder thread has written `res`
    os._exit(0)


def _timed(calls: list[float], fn: Any, *args: Any) -> Any:
    t0 = time.perf_counter()
    value = fn(*args)
    calls.append(time.perf_counter() - t0)
    return value


def _moves(c: Any, r: Any, calls: dict[str, list[float]], res: dict[str, Any]) -> bool:
    """The program's body; True when every call succeeded and the arm is back where it began."""
    failed: list[str] = []
    q0 = list(r.getActualQ())
    qa = [q0[0] + 0.3, q0[1] - 0.2, q0[2] + 0.2, q0[3], q0[4], q0[5] + 0.3]
    if not _timed(calls["moveJ"], c.moveJ, qa, 1.05, 1.4):
        failed.append("moveJ out")
    pose = list(r.getActualTCPPose())
    down = [*pose[:2], pose[2] - 0.05, *pose[3:]]
    side = [pose[0] + 0.05, *down[1:]]
    for name, target in (("moveL down", down), ("moveL side", side)):
        if not _timed(calls["moveL"], c.moveL, target, 0.25, 1.2):
            failed.append(name)
    reached = list(r.getActualTCPPose())
    res["moveL_error_m"] = max(abs(a - b) for a, b in zip(reached[:3], side[:3], strict=True))
    for _ in range(5):
        fk = _timed(calls["command"], c.getForwardKinematics)
        if len(fk) != 6:
            failed.append("getForwardKinematics")
        _timed(calls["command"], c.isSteady)
    for _ in range(50):
        _timed(calls["read"], r.getActualQ)
        _timed(calls["read"], r.getActualTCPPose)
        _timed(calls["read"], r.getRobotMode)
    if r.getRobotMode() != 7 or r.getSafetyMode() != 1:
        failed.append(f"robot mode {r.getRobotMode()}, safety mode {r.getSafetyMode()}")
    if not _timed(calls["moveJ"], c.moveJ, q0, 1.05, 1.4):
        failed.append("moveJ back")
    back = list(r.getActualQ())
    res["home_error_rad"] = max(abs(a - b) for a, b in zip(back, q0, strict=True))
    if res["home_error_rad"] > 0.01:
        failed.append(f"not back home ({res['home_error_rad']:.4f} rad off)")
    res["failed"] = failed
    return not failed


# -- raw RTDE receivers (in the bench process) ---------------------------------------------------


def _package(kind: str, payload: bytes = b"") -> bytes:
    return struct.pack(">HB", 3 + len(payload), ord(kind)) + payload


def _answer(sock: socket.socket, want: str) -> bytes:
    """The payload of the next package of type `want` (blocking; others skipped)."""
    buf = b""
    while True:
        while len(buf) >= 3:
            size, kind = struct.unpack(">HB", buf[:3])
            if len(buf) < size:
                break
            body, buf = buf[3:size], buf[size:]
            if chr(kind) == want:
                return body  # what follows (the first data packages) is not counted
        data = sock.recv(65536)
        if not data:
            raise ConnectionError(f"closed before the {want!r} answer")
        buf += data


@dataclass
class Receiver:
    """One raw RTDE client streaming `RECEIVE_RECIPE` from one address."""

    address: str
    frequency: float
    sock: socket.socket | None = None
    size: int = 0  # bytes of one data package, header included
    nbytes: int = 0  # data bytes received since the window began
    first: float | None = None
    last: float | None = None
    max_gap_s: float = 0.0
    error: str | None = None

    def connect(self) -> None:
        sock = socket.create_connection((self.address, RTDE_PORT), timeout=30)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(_package("V", struct.pack(">H", 2)))
        if _answer(sock, "V") != b"\x01":
            raise RuntimeError("protocol version 2 not accepted")
        setup = struct.pack(">d", self.frequency) + RECEIVE_RECIPE.encode()
        sock.sendall(_package("O", setup))
        body = _answer(sock, "O")
        if body[0] == 0:
            raise RuntimeError(f"recipe refused: {body[1:].decode()}")
        types = body[1:].decode().split(",")
        self.size = 3 + 1 + sum(_TYPE_SIZE[t] for t in types)
        sock.sendall(_package("S"))
        if _answer(sock, "S") != b"\x01":
            raise RuntimeError("start refused")
        sock.setblocking(False)
        self.sock = sock

    def received(self, n: int, now: float) -> None:
        self.nbytes += n
        if self.last is not None:
            self.max_gap_s = max(self.max_gap_s, now - self.last)
        if self.first is None:
            self.first = now
        self.last = now

    @property
    def packages(self) -> int:
        return self.nbytes // self.size if self.size else 0

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()


_TYPE_SIZE = {"DOUBLE": 8, "VECTOR6D": 48, "VECTOR3D": 24, "INT32": 4, "UINT32": 4}
_TYPE_SIZE |= {"UINT64": 8, "UINT8": 1, "BOOL": 1, "VECTOR6INT32": 24, "VECTOR6UINT32": 24}


def receive(
    addresses: list[str],
    frequency: float,
    warmup_s: float,
    window_s: float,
    at_start: Callable[[], object] = lambda: None,
) -> dict:
    """One raw receiver per address, all at once: after `warmup_s`, count for `window_s`
    (`at_start()` is called when counting begins). Returns {"receivers": [Receiver],
    "window": (t0, t1)} (perf_counter times)."""
    receivers = [Receiver(a, frequency) for a in addresses]
    for rx in receivers:
        try:
            rx.connect()
        except Exception as exc:
            rx.error = f"{type(exc).__name__}: {exc}"
    sel = selectors.DefaultSelector()
    for rx in receivers:
        if rx.sock is not None:
            sel.register(rx.sock, selectors.EVENT_READ, rx)
    begin = time.perf_counter()
    t0, t1 = begin + warmup_s, begin + warmup_s + window_s
    counting = False
    try:
        while (now := time.perf_counter()) < t1:
            if not counting and now >= t0:
                counting = True
                at_start()
            for key, _ in sel.select(timeout=0.05):
                rx = key.data
                try:
                    data = rx.sock.recv(262144)
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError as exc:
                    data, rx.error = b"", f"{type(exc).__name__}: {exc}"
                if not data:
                    rx.error = rx.error or "closed by the service"
                    sel.unregister(rx.sock)
                    continue
                if counting:
                    rx.received(len(data), time.perf_counter())
    finally:
        sel.close()
        for rx in receivers:
            rx.close()
    return {"receivers": receivers, "window": (t0, t1)}
