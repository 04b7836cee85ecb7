"""What the Tk and terminal controllers share: a view model and an asyncio backend.

`ControllerModel` is plain Python (no widgets, no I/O): it takes events (Info, WorldState,
CommandAck, ConnectionStatus, Notice) and says what the rows, the jog block (`JogPad`,
clients/apps/jog.py) and the status line show. The UIs only copy its texts into widgets, so
the view logic is tested without a display.

`ControllerBackend` does all network work on an asyncio loop: it streams the chosen world over
the WebSocket (reconnecting when the server goes away) and sends the button presses as HTTP
commands (Up/Down, jog steps, gripper, reset). It reports everything through one `emit(event)`
callback; the Tk app runs it on a background thread and passes events through a queue, the
textual app runs it on its own loop.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from clients.apps.jog import JogPad, button_text
from clients.async_client import AsyncArmfleetClient
from clients.cartesian import AXES
from clients.errors import ArmfleetError, NotFound, Unreachable
from clients.models import CommandAck, ConnectionStatus, Info, ResetResult, WorldState

TITLE = "Robot Joint Controller"
STEP = 0.1  # rad per Up/Down press, as in the seed
GRIPPER_JOINT = "finger_joint"  # Open/Close drive it to its lower/upper limit (from /v1/info)
STREAM_RATE = 30.0  # state frames per second for the live "measured" column


@dataclass(frozen=True)
class Notice:
    """Something to tell the user on the status line (a failed command, a bad world...)."""

    text: str
    error: bool = True
    until_connected: bool = False  # about the connection: cleared once the stream is back


@dataclass(frozen=True)
class WorldSelected:
    """The backend now streams and commands this world."""

    world: int


Event = Info | WorldState | CommandAck | ResetResult | ConnectionStatus | Notice | WorldSelected


def _fmt(value: float | None) -> str:
    if value is None:
        return "--"
    text = f"{value:.2f}"
    return "0.00" if text == "-0.00" else text


class ControllerModel:
    """State of one controller window, updated from backend events.

    Targets come from command replies (the server's clamped value) and from state frames at or
    after the tick a reply named, so a frame from before a press never undoes the label.
    """

    def __init__(self, url: str, world: int) -> None:
        self.url = url
        self.world = world
        self.nworld: int | None = None
        self.names: list[str] = []  # no rows until /v1/info (or a state) names the joints
        self.home: list[float] | None = None
        self.targets: list[float | None] = [None] * len(self.names)
        self.positions: list[float | None] = [None] * len(self.names)
        self.selected = 0  # a row of the keyboard's cursor: the joints', then the jog axes'
        self.jog = JogPad()
        self.tick: int | None = None
        self.connected = False
        self.link = f"connecting to {url}..."
        self.notice: Notice | None = None
        self._ack_tick = -1

    # -- events ------------------------------------------------------------------------------

    def apply(self, event: Event) -> None:
        if isinstance(event, Info):
            self.apply_info(event)
        elif isinstance(event, WorldState):
            self.apply_state(event)
        elif isinstance(event, CommandAck):
            self.apply_ack(event)
        elif isinstance(event, ResetResult):
            self.apply_reset(event)
        elif isinstance(event, ConnectionStatus):
            self.apply_status(event)
        elif isinstance(event, Notice):
            self.notice = event
        elif isinstance(event, WorldSelected):
            self.select_world(event.world)

    def apply_info(self, info: Info) -> None:
        self.nworld = info.nworld
        if info.names != self.names:
            self.names = info.names
            self.targets = [None] * len(self.names)
            self.positions = [None] * len(self.names)
            self.selected = 0  # the rows moved: back to the first
        self.home = [j.home for j in info.joints]

    def apply_state(self, state: WorldState) -> None:
        if state.world != self.world:
            return  # a late frame of the world we just left
        if list(state.name) != self.names:
            self.names = list(state.name)
            self.targets = [None] * len(self.names)
        self.positions = [float(v) for v in state.position]
        if state.tick >= self._ack_tick:
            self.targets = [float(v) for v in state.target]
        self.tick = state.tick
        self.connected = True

    def apply_ack(self, ack: CommandAck) -> None:
        if ack.world != self.world:
            return
        self.targets = [float(v) for v in ack.target]
        self._ack_tick = max(self._ack_tick, ack.tick)
        if ack.clamped:
            self.notice = Notice(f"clamped at the joint limit: {', '.join(ack.clamped)}", False)
        elif self.notice is not None and not self.notice.error:
            self.notice = None

    def apply_reset(self, reset: ResetResult) -> None:
        """A reset sends the world's targets home, from `reset.tick` on."""
        if self.world not in reset.worlds:
            return
        if self.home is not None and len(self.home) == len(self.names):
            self.targets = list(self.home)
        self._ack_tick = max(self._ack_tick, reset.tick)
        self.notice = Notice(f"world {self.world} reset", error=False)

    def apply_status(self, status: ConnectionStatus) -> None:
        self.connected = status.connected
        self._ack_tick = -1  # a restarted server counts ticks from 0 again
        if status.connected:
            self.link = "connected"
            if self.notice is not None and self.notice.until_connected:
                self.notice = None
        else:
            retry = "" if status.retry_in is None else f"; retrying in {status.retry_in:.1f} s"
            self.link = f"server gone ({status.detail}){retry} [attempt {status.attempt}]"

    def select_world(self, world: int) -> None:
        if world == self.world:
            return
        self.world = world
        self.targets = [None] * len(self.names)
        self.positions = [None] * len(self.names)
        self.tick = None
        self._ack_tick = -1

    # -- user input --------------------------------------------------------------------------

    def move_selection(self, step: int) -> int:
        """Move the cursor over the joint rows and then the jog rows, wrapping around."""
        if self.names:
            self.selected = (self.selected + step) % (len(self.names) + len(AXES))
        return self.selected

    def selected_joint(self) -> str | None:
        """The joint the keyboard acts on (None until the joints are known, or on a jog row)."""
        return self.names[self.selected] if self.selected < len(self.names) else None

    def selected_axis(self) -> str | None:
        """The jog axis the keyboard acts on (None on a joint row or before the joints)."""
        k = self.selected - len(self.names)
        return AXES[k] if self.names and 0 <= k < len(AXES) else None

    def clamp_world(self, world: int) -> int:
        """A world id the server has (wraps around when nworld is known)."""
        if self.nworld:
            return world % self.nworld
        return max(0, world)

    # -- texts -------------------------------------------------------------------------------

    def joint_label(self, i: int) -> str:
        return f"[{i}] {self.names[i]}"

    def target_text(self, i: int) -> str:
        return _fmt(self.targets[i])

    def measured_text(self, i: int) -> str:
        return _fmt(self.positions[i])

    def world_text(self) -> str:
        n = "?" if self.nworld is None else str(self.nworld - 1)
        return f"world {self.world} (0..{n})"

    def status_text(self) -> str:
        if self.connected:
            tick = "" if self.tick is None else f", tick {self.tick}"
            text = f"Connected to {self.url}: {self.world_text()}{tick}"
        else:
            text = f"{self.url}: {self.link}"
        if self.notice is not None:
            text += f" | {self.notice.text}"
        return text


class ControllerBackend:
    """Network side of a controller, on one asyncio loop. Every outcome goes to `emit`."""

    def __init__(
        self,
        url: str,
        world: int,
        emit: Callable[[Event], None],
        rate: float = STREAM_RATE,
        timeout: float = 5.0,
        token: str | None = None,
    ) -> None:
        self.url = url
        self.world = world
        self.emit = emit
        self.rate = rate
        self.client = AsyncArmfleetClient(url, timeout=timeout, token=token)
        self._switch = asyncio.Event()
        self._info_task: asyncio.Task[None] | None = None
        self.info: Info | None = None  # the last /v1/info read

    async def run(self) -> None:
        """Stream the current world until cancelled; restart the stream on a world switch."""
        try:
            while True:
                self._switch.clear()
                stream = asyncio.create_task(self._stream(self.world))
                switch = asyncio.create_task(self._switch.wait())
                try:
                    await asyncio.wait({stream, switch}, return_when=asyncio.FIRST_COMPLETED)
                finally:
                    for task in (stream, switch):
                        task.cancel()
                        with contextlib.suppress(asyncio.CancelledError, Exception):
                            await task
                if stream.done() and not stream.cancelled() and stream.exception() is not None:
                    # Not a connection problem (those are retried inside): say so, retry slowly.
                    self.emit(Notice(f"stream stopped: {stream.exception()!r}"))
                    await asyncio.sleep(2.0)
        finally:
            if self._info_task is not None:
                self._info_task.cancel()
            await self.client.close()

    async def _stream(self, world: int) -> None:
        def on_status(status: ConnectionStatus) -> None:
            self.emit(status)
            if status.connected:  # (re)connected: the server may have been restarted
                self._info_task = asyncio.ensure_future(self._load_info())

        try:
            async for state in self.client.stream(world, self.rate, on_status=on_status):
                self.emit(state)
        except NotFound as exc:
            self.emit(Notice(f"world {world}: {exc}"))
            await self._load_info()
            await asyncio.Event().wait()  # nothing to stream until another world is chosen

    async def _load_info(self) -> None:
        with contextlib.suppress(ArmfleetError):
            self.info = await self.client.info()
            self.emit(self.info)

    # -- commands (each reports its reply or its failure) ------------------------------------

    async def _command(self, what: str, coro: Any) -> None:
        try:
            self.emit(await coro)
        except Unreachable:
            self.emit(Notice(f"{what} failed: server unreachable", until_connected=True))
        except ArmfleetError as exc:
            self.emit(Notice(f"{what} failed: {exc}"))

    async def increment(self, joint: int | str, delta: float) -> None:
        sign = "Up" if delta > 0 else "Down"
        await self._command(sign, self.client.increment(self.world, joint, delta))

    async def jog(self, axis: str, step: float, frame: str) -> None:
        """One pendant step; a step out of reach comes back as a Notice with the server's
        reason (`Jog +Z (base) failed: HTTP 422: body.step: the step leaves the arm's reach`)."""
        what = f"Jog {button_text(axis, 1 if step > 0 else -1)} ({frame})"
        await self._command(what, self.client.jog(self.world, axis, step, frame))

    async def gripper(self, closed: bool) -> None:
        """Close: the gripper joint to its upper limit; Open: to its lower (as the served
        model states them)."""

        async def command() -> CommandAck:
            info = self.info or await self.client.info()
            joint = info.joint(GRIPPER_JOINT)
            value = joint.upper if closed else joint.lower
            return await self.client.set_targets(self.world, {joint.name: value})

        await self._command("Close" if closed else "Open", command())

    async def reset(self) -> None:
        await self._command("Reset", self.client.reset(self.world))

    async def select_world(self, world: int) -> None:
        if world == self.world:
            return
        self.world = world
        self.emit(WorldSelected(world))
        self._switch.set()
