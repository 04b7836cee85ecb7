"""Terminal twin of the Tk controller (textual): the same seven rows and jog block, by keys.

    up/down or k/j   pick a row            +/- or right/left   target ±0.1, or jog ±step
    t                base / tool frame     s / S               jog step size: next / previous
    o / c            open / close gripper  r                   reset the world
    w / W or ] / [   next / previous world q                   quit

Below the joint rows, six jog rows (X Y Z [m], Rx Ry Rz [rad]): on one of them +/- sends a
pendant jog step in the frame and of the size the jog line shows (`JogPad`); a refused step
(out of reach) shows the server's reason on the status line.

Network work runs on textual's asyncio loop in workers (`ControllerBackend`), never blocking
the screen; rows and status line show what `ControllerModel` says.
"""

from __future__ import annotations

from typing import Any, ClassVar

from rich.table import Table
from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.widgets import Footer, Static

from clients.apps.controller import STEP, TITLE, ControllerBackend, ControllerModel, Event
from clients.cartesian import AXES

HELP = (
    "up/down j/k: row   +/- right/left: ±0.1 or jog   t: base/tool   s/S: jog step\n"
    "o/c: open/close gripper   r: reset   w/W ]/[: world   q: quit"
)


class ControllerApp(App[None]):
    TITLE = TITLE
    CSS = """
    #title { padding: 0 1; text-style: bold; }
    #rows { padding: 0 1; height: auto; }
    #jog { padding: 0 1; }
    #help { padding: 0 1; color: $text-muted; }
    #status { padding: 0 1; dock: bottom; height: auto; max-height: 3; margin-bottom: 1; }
    """
    BINDINGS: ClassVar[list[Binding]] = [
        Binding("up,k", "select(-1)", "row up", show=False),
        Binding("down,j", "select(1)", "row down", show=False),
        Binding("plus,equals_sign,right,l", "step(1)", "+0.1 / jog +"),
        Binding("minus,underscore,left,h", "step(-1)", "-0.1 / jog -"),
        Binding("t", "frame", "base/tool"),
        Binding("s", "jog_step(1)", "jog step"),
        Binding("S", "jog_step(-1)", "jog step", show=False),
        Binding("o", "gripper(False)", "open"),
        Binding("c", "gripper(True)", "close"),
        Binding("r", "reset", "reset"),
        Binding("w,right_square_bracket", "world(1)", "next world"),
        Binding("W,left_square_bracket", "world(-1)", "prev world"),
        Binding("q", "quit", "quit"),
    ]

    def __init__(self, url: str, world: int, token: str | None = None) -> None:
        super().__init__()
        self.model = ControllerModel(url.rstrip("/"), world)
        self.backend = ControllerBackend(self.model.url, world, self.on_backend_event, token=token)

    def compose(self) -> ComposeResult:
        yield Static(id="title")
        yield Static(id="rows")
        yield Static(id="jog")
        yield Static(HELP, id="help")
        yield Static(id="status")
        yield Footer()

    def on_mount(self) -> None:
        self.run_worker(self.backend.run(), name="stream", exit_on_error=False)
        self.refresh_view()

    # -- backend -> view ---------------------------------------------------------------------

    def on_backend_event(self, event: Event) -> None:
        self.model.apply(event)
        self.refresh_view()

    def refresh_view(self) -> None:
        m = self.model
        self.query_one("#title", Static).update(f"{TITLE}: {m.world_text()}")
        table = Table(box=None, show_edge=False, pad_edge=False, header_style="bold")
        table.add_column(" ", width=1)
        table.add_column("Joint", width=25)
        table.add_column("Target", justify="right", width=7)
        table.add_column("Measured", justify="right", width=8)
        for i in range(len(m.names)):
            mark = ">" if i == m.selected else " "
            style = "reverse" if i == m.selected else ""
            table.add_row(mark, m.joint_label(i), m.target_text(i), m.measured_text(i), style=style)
        table.add_section()
        for k, axis in enumerate(AXES):
            on = m.selected == len(m.names) + k
            label = Text(m.jog.row_label(axis))  # Text: "[m]" is no markup
            step = m.jog.row_step_text(axis)
            table.add_row(">" if on else " ", label, step, "", style="reverse" if on else "")
        self.query_one("#rows", Static).update(table)
        self.query_one("#jog", Static).update(m.jog.summary())
        color = "green" if m.connected else "red"
        self.query_one("#status", Static).update(Text(m.status_text(), style=color))

    # -- keys -> backend (workers: the screen never waits on the network) ---------------------

    def _spawn(self, coro: Any) -> None:
        self.run_worker(coro, group="commands", exit_on_error=False)

    def action_select(self, step: int) -> None:
        self.model.move_selection(step)
        self.refresh_view()

    def action_step(self, sign: int) -> None:
        joint, axis, jog = self.model.selected_joint(), self.model.selected_axis(), self.model.jog
        if joint is not None:
            self._spawn(self.backend.increment(joint, sign * STEP))
        elif axis is not None:
            self._spawn(self.backend.jog(axis, jog.step(axis, sign), jog.frame))

    def action_frame(self) -> None:
        self.model.jog.toggle_frame()
        self.refresh_view()

    def action_jog_step(self, by: int) -> None:
        self.model.jog.cycle_step(by)
        self.refresh_view()

    def action_gripper(self, closed: bool) -> None:
        self._spawn(self.backend.gripper(closed))

    def action_reset(self) -> None:
        self._spawn(self.backend.reset())

    def action_world(self, step: int) -> None:
        world = self.model.clamp_world(self.model.world + step)
        self.model.select_world(world)
        self._spawn(self.backend.select_world(world))
        self.refresh_view()


def run_tui(url: str, world: int, token: str | None = None) -> None:
    """Run the terminal controller for `world` of the service at `url` until q; `token`: the
    administrator's or a lease's, sent with every command."""
    ControllerApp(url, world, token).run()
