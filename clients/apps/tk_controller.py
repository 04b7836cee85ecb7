"""The seed's Tk button controller, driving one world of an armfleet service.

One row per joint: `[i] name`, the target (2 decimals, as the server replied: clamped as the
server clamps), the measured position (live from the WebSocket), "Up (+0.1)" and "Down (-0.1)".
Above: a world selector and Reset; below: the pendant's jog block (a base/tool frame switch, a
step size, -/+ for X Y Z and Rx Ry Rz: `JogPad`), gripper Open / Close and a status line, where
a refused command (a jog out of reach) says the server's reason.

The network never runs on the Tk thread: a background thread runs an asyncio loop with a
`ControllerBackend`; button handlers schedule coroutines on it and its events come back through
a queue that `root.after` drains. Widgets only show what `ControllerModel` says.

Set ARMFLEET_TK_GEOMETRY_FILE to a path and the window writes (and keeps up to date) a JSON file
with every button's position inside the window and the texts on show: for UI tests that click
with a real pointer (xdotool) and read back what the window displays.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import queue
import signal
import threading
import time
import tkinter as tk
from collections.abc import Coroutine
from pathlib import Path
from typing import Any

from clients.apps.controller import (
    STEP,
    TITLE,
    ControllerBackend,
    ControllerModel,
    Event,
)
from clients.apps.jog import FRAMES, button_text, step_text, step_texts
from clients.cartesian import AXES

POLL_MS = 30  # how often the Tk thread drains backend events
GEOMETRY_ENV = "ARMFLEET_TK_GEOMETRY_FILE"
_TEXTED = (tk.Label, tk.Button, tk.Radiobutton)  # widgets whose text the probe reports


class _BackendThread:
    """An asyncio loop on a daemon thread running the backend; thread-safe `submit`."""

    def __init__(
        self, url: str, world: int, events: queue.Queue[Event], token: str | None = None
    ) -> None:
        self.loop = asyncio.new_event_loop()
        self.backend: ControllerBackend | None = None
        self._ready = threading.Event()
        self._main: asyncio.Task[None] | None = None
        self._thread = threading.Thread(
            target=self._run, args=(url, world, events, token), name="armfleet-net", daemon=True
        )
        self._thread.start()
        self._ready.wait()

    def _run(self, url: str, world: int, events: queue.Queue[Event], token: str | None) -> None:
        asyncio.set_event_loop(self.loop)
        self.backend = ControllerBackend(url, world, events.put, token=token)
        self._main = self.loop.create_task(self.backend.run())
        self._ready.set()
        with contextlib.suppress(asyncio.CancelledError):
            self.loop.run_until_complete(self._main)
        self.loop.close()

    def submit(self, coro: Coroutine[Any, Any, None]) -> None:
        asyncio.run_coroutine_threadsafe(coro, self.loop)

    def stop(self) -> None:
        if self._main is not None and not self.loop.is_closed():
            with contextlib.suppress(RuntimeError):
                self.loop.call_soon_threadsafe(self._main.cancel)
        self._thread.join(timeout=2)


class TkController:
    """The window. Build it with a Tk root; `run_tk` wires it to the network."""

    def __init__(self, root: tk.Tk, model: ControllerModel, net: _BackendThread | None) -> None:
        self.root = root
        self.model = model
        self.net = net
        self.events: queue.Queue[Event] = queue.Queue()
        self._rows: list[dict[str, tk.Widget]] = []
        self._shown: dict[str, str] = {}
        self._probe = os.environ.get(GEOMETRY_ENV)
        self._probe_written = 0.0
        self._probe_dirty = True
        self._probe_scheduled = False

        root.title(TITLE)
        root.minsize(450, 350)

        top = tk.Frame(root)
        top.grid(row=0, column=0, sticky="ew", padx=6, pady=(6, 2))
        tk.Label(top, text="World:").pack(side="left")
        self.world_var = tk.StringVar(value=str(model.world))
        self.world_box = tk.Spinbox(
            top, from_=0, to=9999, width=5, textvariable=self.world_var, command=self._on_world
        )
        self.world_box.bind("<Return>", lambda _e: self._on_world())
        self.world_box.pack(side="left", padx=4)
        self.world_range = tk.Label(top, text="")
        self.world_range.pack(side="left")
        self.reset_button = tk.Button(top, text="Reset", command=self._on_reset)
        self.reset_button.pack(side="right")

        self.table = tk.Frame(root)
        self.table.grid(row=1, column=0, sticky="nsew", padx=6)
        self._build_rows()

        self.jog_box = tk.Frame(root)
        self.jog_box.grid(row=2, column=0, sticky="w", padx=6, pady=(6, 0))
        self._build_jog()

        grip = tk.Frame(root)
        grip.grid(row=3, column=0, sticky="w", padx=6, pady=4)
        tk.Label(grip, text="Gripper:", width=25, anchor="w").pack(side="left")
        self.open_button = tk.Button(grip, text="Open", command=lambda: self._on_gripper(False))
        self.open_button.pack(side="left")
        self.close_button = tk.Button(grip, text="Close", command=lambda: self._on_gripper(True))
        self.close_button.pack(side="left", padx=4)

        self.status = tk.Label(root, text="", anchor="w", justify="left", wraplength=560)
        self.status.grid(row=4, column=0, sticky="ew", padx=6, pady=(2, 6))
        root.columnconfigure(0, weight=1)
        self.refresh()

    # -- layout ------------------------------------------------------------------------------

    def _build_rows(self) -> None:
        for child in self.table.winfo_children():
            child.destroy()
        for col, text in enumerate(("Joint", "Target", "Measured")):
            tk.Label(self.table, text=text, fg="gray30").grid(row=0, column=col, sticky="w")
        self._rows = []
        for i, name in enumerate(self.model.names):
            label = tk.Label(self.table, text=self.model.joint_label(i), width=25, anchor="w")
            target = tk.Label(self.table, text="0.00", width=6)
            measured = tk.Label(self.table, text="0.00", width=7, fg="gray40")
            up = tk.Button(
                self.table, text=f"Up (+{STEP})", command=lambda j=name: self._on_step(j, STEP)
            )
            down = tk.Button(
                self.table, text=f"Down (-{STEP})", command=lambda j=name: self._on_step(j, -STEP)
            )
            for col, widget in enumerate((label, target, measured, up, down)):
                widget.grid(row=i + 1, column=col, padx=2, pady=1, sticky="w")
            self._rows.append(
                {"label": label, "target": target, "measured": measured, "up": up, "down": down}
            )
        self._row_names = list(self.model.names)
        self._shown.clear()
        self._probe_dirty = True

    def _build_jog(self) -> None:
        """The pendant's jog: the frame switch and step size, then -/+ per axis, three a line."""
        head = tk.Frame(self.jog_box)
        head.grid(row=0, column=0, columnspan=8, sticky="w")
        tk.Label(head, text="Jog TCP, frame:").pack(side="left")
        self.frame_var = tk.StringVar(value=self.model.jog.frame)
        self.frame_buttons: dict[str, tk.Radiobutton] = {}
        for frame in FRAMES:
            button = tk.Radiobutton(
                head, text=frame, value=frame, variable=self.frame_var, command=self._on_frame
            )
            button.pack(side="left")
            self.frame_buttons[frame] = button
        tk.Label(head, text="  step:").pack(side="left")
        self.step_var = tk.StringVar()
        self.step_box = tk.Spinbox(
            head,
            values=step_texts(),
            textvariable=self.step_var,
            state="readonly",
            width=16,
            wrap=False,
            command=self._on_step_size,
        )
        self.step_var.set(step_text(self.model.jog.step_index))  # after `values` set the first
        self.step_box.pack(side="left", padx=4)
        self.jog_buttons: dict[str, tk.Button] = {}
        for k, axis in enumerate(AXES):
            row, col = 1 + k // 3, (k % 3) * 3
            for sign, c in ((-1, col), (1, col + 1)):
                button = tk.Button(
                    self.jog_box,
                    text=button_text(axis, sign),
                    width=4,
                    command=lambda a=axis, s=sign: self._on_jog(a, s),
                )
                button.grid(row=row, column=c, padx=1, pady=1)
                self.jog_buttons[f"jog:{'+' if sign > 0 else '-'}{axis}"] = button
            self.jog_box.columnconfigure(col + 2, minsize=14)  # a gap between the axes

    # -- user input (Tk thread): schedule on the network thread, never wait --------------------

    def _submit(self, coro: Coroutine[Any, Any, None]) -> None:
        if self.net is not None:
            self.net.submit(coro)
        else:
            coro.close()

    def _backend(self) -> ControllerBackend | None:
        return None if self.net is None else self.net.backend

    def _on_step(self, joint: str, delta: float) -> None:
        if backend := self._backend():
            self._submit(backend.increment(joint, delta))

    def _on_jog(self, axis: str, sign: int) -> None:
        jog = self.model.jog
        if backend := self._backend():
            self._submit(backend.jog(axis, jog.step(axis, sign), jog.frame))

    def _on_frame(self) -> None:
        self.model.jog.set_frame(self.frame_var.get())
        self._probe_dirty = True
        self._write_probe()

    def _on_step_size(self) -> None:
        self.model.jog.set_step_text(self.step_var.get())
        self._probe_dirty = True
        self._write_probe()

    def _on_gripper(self, closed: bool) -> None:
        if backend := self._backend():
            self._submit(backend.gripper(closed))

    def _on_reset(self) -> None:
        if backend := self._backend():
            self._submit(backend.reset())

    def _on_world(self) -> None:
        try:
            wanted = int(self.world_var.get())
        except ValueError:
            self.world_var.set(str(self.model.world))
            return
        world = self.model.clamp_world(wanted)
        self.world_var.set(str(world))
        if world != self.model.world:
            self.model.select_world(world)
            if backend := self._backend():
                self._submit(backend.select_world(world))
            self.refresh()

    # -- backend events (drained on the Tk thread) -------------------------------------------

    def poll(self) -> None:
        changed = False
        while True:
            try:
                event = self.events.get_nowait()
            except queue.Empty:
                break
            self.model.apply(event)
            changed = True
        if changed:
            self.refresh()
        self.root.after(POLL_MS, self.poll)

    def _set(self, key: str, widget: tk.Widget, text: str) -> None:
        if self._shown.get(key) != text:
            self._shown[key] = text
            widget.configure(text=text)
            self._probe_dirty = True

    def refresh(self) -> None:
        m = self.model
        if m.names != self._row_names:
            self._build_rows()
        for i, row in enumerate(self._rows):
            self._set(f"label:{i}", row["label"], m.joint_label(i))
            self._set(f"target:{m.names[i]}", row["target"], m.target_text(i))
            self._set(f"measured:{m.names[i]}", row["measured"], m.measured_text(i))
        top = "?" if m.nworld is None else str(m.nworld - 1)
        self._set("world_range", self.world_range, f"of 0..{top}")
        if m.nworld is not None:
            self.world_box.configure(to=m.nworld - 1)
        if self.root.focus_get() is not self.world_box and self.world_var.get() != str(m.world):
            self.world_var.set(str(m.world))
        self._set("status", self.status, m.status_text())
        self._write_probe()

    # -- test probe --------------------------------------------------------------------------

    def widgets(self) -> dict[str, tk.Widget]:
        out: dict[str, tk.Widget] = {
            "world": self.world_box,
            "reset": self.reset_button,
            "open": self.open_button,
            "close": self.close_button,
            "status": self.status,
            "step": self.step_box,
            **{f"frame:{f}": b for f, b in self.frame_buttons.items()},
            **self.jog_buttons,
        }
        for name, row in zip(self._row_names, self._rows, strict=True):
            for key in ("label", "up", "down", "target", "measured"):
                out[f"{key}:{name}"] = row[key]
        return out

    def _write_probe(self) -> None:
        if not self._probe or not self._probe_dirty:
            return
        now = time.monotonic()
        if now - self._probe_written < 0.1:  # at most ~10 writes a second
            if not self._probe_scheduled:
                self._probe_scheduled = True
                self.root.after(120, self._deferred_probe)
            return
        self.root.update_idletasks()
        x0, y0 = self.root.winfo_rootx(), self.root.winfo_rooty()
        geometry = {
            key: {
                "x": w.winfo_rootx() - x0,
                "y": w.winfo_rooty() - y0,
                "width": w.winfo_width(),
                "height": w.winfo_height(),
                **({"text": w.cget("text")} if isinstance(w, _TEXTED) else {}),
            }
            for key, w in self.widgets().items()
        }
        probe = {
            "title": self.root.title(),
            "window": {"width": self.root.winfo_width(), "height": self.root.winfo_height()},
            "world": self.model.world,
            "nworld": self.model.nworld,
            "connected": self.model.connected,
            "status": self.model.status_text(),
            "jog": {"frame": self.model.jog.frame, "step": step_text(self.model.jog.step_index)},
            "widgets": geometry,
        }
        path = Path(self._probe)
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(json.dumps(probe, indent=1))
        tmp.replace(path)
        self._probe_written = now
        self._probe_dirty = False

    def _deferred_probe(self) -> None:
        self._probe_scheduled = False
        self._write_probe()


def run_tk(url: str, world: int, token: str | None = None) -> None:
    """Open the controller window for `world` of the service at `url`; returns when closed.
    `token`: the administrator's or a lease's, sent with every command."""
    root = tk.Tk()
    model = ControllerModel(url.rstrip("/"), world)
    app = TkController(root, model, None)
    app.net = _BackendThread(model.url, world, app.events, token)

    def quit_app() -> None:
        if app.net is not None:
            app.net.stop()
        root.destroy()

    root.protocol("WM_DELETE_WINDOW", quit_app)
    for sig in (signal.SIGINT, signal.SIGTERM):  # handled between polls, on the Tk thread
        signal.signal(sig, lambda *_: root.after(0, quit_app))
    root.after(POLL_MS, app.poll)
    try:
        root.mainloop()
    except KeyboardInterrupt:
        quit_app()
