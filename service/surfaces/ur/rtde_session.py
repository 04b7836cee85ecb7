"""One RTDE connection: the handshake, recipes, start/pause, and the data packages.

Protocol version 2 only (ur_rtde and UR's own client ask for it; version 1 is answered "not
accepted"). An output recipe with a `NOT_FOUND` variable, or an input recipe with a
`NOT_FOUND` or `IN_USE` one (an input another connection to the same world already writes),
is answered with recipe id 0 and its type list, as the robot fails a setup, and is not kept.
Started output recipes are sent at their frequency (1..500 Hz), each package from the world's
state at the latest tick (the same bytes again while neither the tick nor the controller
moved), every stream of one frequency from one timer (rtde_pacer.py); a client too slow to
read has packages skipped, never queued without bound.

Malformed input never ends the service or reaches another world: a package too short for its
fields or naming an unknown recipe gets a text message (level ERROR) and a log line; a header
that cannot be framed closes this connection with a log line.

A data package *longer* than its recipe's fields is applied by those fields and the rest is
ignored (one log line per recipe of a connection). Why: ur-rtde 1.6.5 sends such packages, and
on purpose. Its `getForwardKinematics(q, tcp_offset)` with an all-zero offset sends the command
of `getForwardKinematics(q)` (44, recipe of six doubles) with the offset's six zeros appended
(librtde.so.1.6.5, `RTDEControlInterface::getForwardKinematics`: an all-zero offset takes the
q-only branch, then the offset is appended anyway): a call that returns on the controllers it
was released against only if a controller reads a package by its recipe. Refusing it left that
call waiting for an answer that never came.
"""

from __future__ import annotations

import asyncio
import logging
import math
import socket
import struct
from typing import TYPE_CHECKING, cast

from service.surfaces.ur import rtde_variables as rv
from service.surfaces.ur import rtde_wire as wire
from service.surfaces.ur.rtde_outputs import OutputRecipe, WorldTick, apply_inputs
from service.surfaces.ur.world_robot import GAP_WARN_S

if TYPE_CHECKING:
    from service.surfaces.ur.world_robot import WorldRobot

log = logging.getLogger("armfleet.ur")
_MAX_BUFFERED = 4 * wire.MAX_PACKAGE  # unread input bytes before the connection is closed
_MAX_UNSENT = 256 * 1024  # bytes waiting in the socket before packages are skipped
_MAX_RECIPES = 255


class RtdeSession(asyncio.Protocol):
    """One client of one world's RTDE port (runs on the UR event loop)."""

    def __init__(self, robot: WorldRobot) -> None:
        self.robot = robot
        self.transport: asyncio.Transport | None = None
        self._buffer = bytearray()
        self._outputs: dict[int, OutputRecipe] = {}
        self._inputs: dict[int, tuple[tuple[str, ...], struct.Struct]] = {}
        self._next_id = {"out": 1, "in": 1}  # outputs and inputs are numbered apart
        self._overlong: set[int] = set()  # input recipes a package longer than them came for
        self._streams: dict[int, _Stream] = {}  # recipe id → its stream, while started
        self.started = False
        self.sent = 0  # data packages sent
        self.skipped = 0  # data packages skipped for a slow reader

    # -- asyncio.Protocol -------------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # a stream transport (uvloop's is not an asyncio.Transport subclass: endpoints.py)
        self.transport = cast(asyncio.Transport, transport)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.robot.opened(self)

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_streaming()
        self.robot.closed(self)

    def data_received(self, data: bytes) -> None:
        self._buffer += data
        try:
            packages = wire.split(self._buffer)
        except wire.Malformed as exc:
            return self.refuse_connection(str(exc))
        if len(self._buffer) > _MAX_BUFFERED:
            return self.refuse_connection("a package larger than the buffer")
        for package in packages:
            if self.transport is None or self.transport.is_closing():
                return
            try:
                self._handle(package)
            except wire.Malformed as exc:
                self._error(f"package {package.name!r}: {exc}")

    # -- packages ---------------------------------------------------------------------------

    def _handle(self, p: wire.Package) -> None:
        kind, body = p.kind, p.payload
        if kind == wire.REQUEST_PROTOCOL_VERSION:
            if len(body) != 2:
                raise wire.Malformed(f"a protocol version is 2 bytes, got {len(body)}")
            version = struct.unpack(">H", body)[0]
            self._send(wire.accepted(kind, version == wire.PROTOCOL_VERSION))
        elif kind == wire.GET_URCONTROL_VERSION:
            self._send(wire.control_version())
        elif kind == wire.TEXT_MESSAGE:
            message, source, level = wire.read_text(body)
            log.info(  # quoted: a client's bytes never make lines of their own in the log
                "world %d RTDE client says (%r, level %d): %r",
                self.robot.world,
                source,
                level,
                message[:200],
            )
        elif kind == wire.SETUP_OUTPUTS:
            self._setup_outputs(body)
        elif kind == wire.SETUP_INPUTS:
            self._setup_inputs(body)
        elif kind == wire.START:
            self._start()
            self._send(wire.accepted(kind, True))
        elif kind == wire.PAUSE:
            self._stop_streaming()
            self._send(wire.accepted(kind, True))
        elif kind == wire.DATA_PACKAGE:
            self._inputs_package(body)
        else:
            self._error(f"unknown package type {p.name!r} ({kind})")

    def _new_id(self, side: str) -> int:
        """The next recipe id of `side` ("out" or "in"): a controller numbers output and
        input recipes each from 1 (ur_rtde sends its first input recipe's data as id 1)."""
        if self._next_id[side] > _MAX_RECIPES:
            raise wire.Malformed(f"more than {_MAX_RECIPES} recipes on one connection")
        self._next_id[side] += 1
        return self._next_id[side] - 1

    def _setup_outputs(self, body: bytes) -> None:
        if len(body) < 8:
            raise wire.Malformed("an output setup starts with its frequency (8 bytes)")
        frequency = struct.unpack(">d", body[:8])[0]
        names = wire.names_of(body[8:])
        types = [rv.output_type(n) for n in names]
        problem = None
        if not (math.isfinite(frequency) and 0 < frequency <= wire.MAX_FREQUENCY):
            problem = f"frequency {frequency} Hz is outside (0, {wire.MAX_FREQUENCY:g}]"
        elif self.started:
            problem = "outputs cannot be set up while synchronising (pause first)"
        elif rv.NOT_FOUND in types:
            problem = f"unknown output variable {names[types.index(rv.NOT_FOUND)]!r}"
        if problem is not None:
            log.info("world %d RTDE output setup refused: %s", self.robot.world, problem)
            self._send(wire.text(problem, level=wire.ERROR))
            self._send(wire.recipe_answer(wire.SETUP_OUTPUTS, 0, types))
            return
        recipe = OutputRecipe.build(self._new_id("out"), names, frequency)
        self._outputs[recipe.id] = recipe
        self._send(wire.recipe_answer(wire.SETUP_OUTPUTS, recipe.id, types))

    def _setup_inputs(self, body: bytes) -> None:
        names = wire.names_of(body)
        types = [rv.input_type(n) for n in names]
        for i, name in enumerate(names):
            if types[i] != rv.NOT_FOUND and not self.robot.may_write(name, self):
                types[i] = rv.IN_USE
        bad = [n for n, t in zip(names, types, strict=True) if t in (rv.NOT_FOUND, rv.IN_USE)]
        if bad or len(set(names)) != len(names):
            log.info("world %d RTDE input setup refused: %s", self.robot.world, ", ".join(bad[:4]))
            self._send(wire.recipe_answer(wire.SETUP_INPUTS, 0, types))
            return
        recipe_id = self._new_id("in")
        self._inputs[recipe_id] = (tuple(names), rv.struct_of(types))
        log.debug("world %d RTDE input recipe %d: %s", self.robot.world, recipe_id, names)
        self.robot.hold_inputs(names, self)
        self._send(wire.recipe_answer(wire.SETUP_INPUTS, recipe_id, types))

    def _inputs_package(self, body: bytes) -> None:
        if not body:
            raise wire.Malformed("a data package without its recipe id")
        recipe = self._inputs.get(body[0])
        if recipe is None:
            raise wire.Malformed(f"no input recipe {body[0]} on this connection")
        names, layout = recipe
        if len(body) - 1 < layout.size:
            raise wire.Malformed(
                f"recipe {body[0]} takes {layout.size} bytes of values, got {len(body) - 1}"
            )
        if len(body) - 1 > layout.size and body[0] not in self._overlong:
            self._overlong.add(body[0])  # said once per recipe (ur_rtde sends it per call)
            log.info(
                "world %d RTDE: recipe %d takes %d bytes of values, a package brought %d: "
                "its fields applied, the rest ignored, as a controller does (module docstring)",
                self.robot.world, body[0], layout.size, len(body) - 1,
            )  # fmt: skip
        values = layout.unpack(body[1 : 1 + layout.size])
        grouped, i = [], 0
        for name in names:
            n = rv.COUNTS[rv.input_type(name)]
            grouped.append(values[i] if n == 1 else list(values[i : i + n]))
            i += n
        apply_inputs(self.robot.controller, names, grouped)
        self.robot.inputs_changed()

    # -- streaming --------------------------------------------------------------------------

    def _start(self) -> None:
        if self.started:
            return
        self.started = True
        self.robot.streaming(+1)
        pacers = self.robot.fleet.pacers
        for recipe in self._outputs.values():
            stream = self._streams[recipe.id] = _Stream(self, recipe)
            pacers.add(recipe.frequency, stream)

    def _stop_streaming(self) -> None:
        pacers = self.robot.fleet.pacers
        for stream in self._streams.values():
            pacers.remove(stream.recipe.frequency, stream)
        self._streams.clear()
        if self.started:
            self.started = False
            self.robot.streaming(-1)

    # -- replies ----------------------------------------------------------------------------

    def _send(self, data: bytes) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)

    def _error(self, why: str) -> None:
        log.warning("world %d RTDE: %s", self.robot.world, why)
        self._send(wire.text(why, level=wire.ERROR))

    def send(self, data: bytes) -> None:
        """Robot messages go to the script ports' clients, not to RTDE's."""

    def refuse_connection(self, why: str) -> None:
        """Close this connection (a package that cannot be framed, or the world not lent)."""
        log.warning("world %d RTDE connection closed: %s", self.robot.world, why)
        if self.transport is not None:
            self.transport.abort()


class _Stream:
    """One started output recipe: its package of the latest view, packed and framed once per
    view (a view is renewed when its frame, controller or payload changes: world_robot.py)
    and sent by the pacer of its frequency (rtde_pacer.py).

    Why it never goes quiet on its own: ur_rtde drops the connection 2.5 s after the last
    package it got. The views come from the latest frame whatever the ticks do (a late or
    paused world's last state is sent again, its timestamp that tick's), and a view that
    cannot be packed (a bug) is logged once and the last package goes on being sent; with no
    package yet, the connection is closed at once rather than left silent. Every send's gap
    to the last one is kept per world (`WorldRobot.rtde_gap`: GET /v1/ur, a log line from
    1 s), so that a starved UR thread is told apart from a client that stopped reading."""

    __slots__ = ("_bytes", "_failed", "_last", "_skipped", "_view", "recipe", "session")

    def __init__(self, session: RtdeSession, recipe: OutputRecipe) -> None:
        self.session, self.recipe = session, recipe
        self._view: object = None
        self._bytes = b""
        self._failed = False  # a view could not be packed (logged once)
        self._last: float | None = None  # event-loop time of the last package sent
        self._skipped = 0  # packages skipped since then for a full socket

    def send_due(self, now: float) -> bool:
        session = self.session
        transport = session.transport
        if transport is None or transport.is_closing() or not session.started:
            return False
        robot = session.robot
        view = robot.view(now)
        if view is None:
            return True
        if view is not self._view and not self._pack(view):
            return False
        if transport.get_write_buffer_size() > _MAX_UNSENT:
            session.skipped += 1
            self._skipped += 1
            return True
        transport.write(self._bytes)
        session.sent += 1
        last = self._last
        if last is not None:
            gap = now - last
            # the call only for a new longest gap or one to log: 32,000 sends a second
            if gap > robot.longest_gap or gap >= GAP_WARN_S:
                robot.rtde_gap(gap, self._skipped)
        self._last, self._skipped = now, 0
        return True

    def _pack(self, view: WorldTick) -> bool:
        """The package of `view`; on failure the last one stays (False: there is none, and
        the connection is closed)."""
        try:
            packed = wire.frame(wire.DATA_PACKAGE, self.recipe.pack(view))
        except Exception:
            if not self._failed:
                self._failed = True
                log.exception(
                    "world %d RTDE recipe %d could not be packed; its last package is sent "
                    "again", self.session.robot.world, self.recipe.id,
                )  # fmt: skip
            if not self._bytes:
                self.session.refuse_connection("its RTDE outputs could not be packed")
                return False
            return True
        self._view, self._bytes = view, packed
        return True
