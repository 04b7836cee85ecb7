"""`armfleet watch`: one world's state stream as a live table, or JSON lines for piping.

JSON mode prints one object per frame (the fields of GET /v1/worlds/{w}/state), flushed at
once; connection news goes to stderr so stdout stays parseable. Both modes reconnect when the
server restarts. Ctrl-C (or a closed pipe) ends it quietly.
"""

from __future__ import annotations

import contextlib
import os
import sys

import orjson
from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from clients.client import ArmfleetClient
from clients.errors import ArmfleetError
from clients.models import ConnectionStatus, WorldState


def state_json(state: WorldState) -> dict[str, object]:
    """A WorldState back in the service's JSON shape."""
    return {
        "world": state.world,
        "tick": state.tick,
        "sim_time": state.sim_time,
        "name": list(state.name),
        "position": state.position.tolist(),
        "velocity": state.velocity.tolist(),
        "effort": state.effort.tolist(),
        "target": state.target.tolist(),
        "flange": {
            "position": state.flange_position.tolist(),
            "quaternion": state.flange_quaternion.tolist(),
        },
        "faults": state.faults,
    }


def render(state: WorldState | None, url: str, world: int, link: str) -> Group:
    """The live view: a header line, a joint table, the flange pose, the connection line."""
    if state is None:
        return Group(Text(f"world {world} at {url}: waiting for the first frame..."), Text(link))
    header = Text(
        f"world {state.world}  tick {state.tick}  sim_time {state.sim_time:.3f} s  "
        f"faults {state.faults}",
        style="bold",
    )
    table = Table(show_edge=False, header_style="bold")
    table.add_column("#", justify="right")
    table.add_column("joint")
    for col in ("position", "target", "velocity", "effort"):
        table.add_column(col, justify="right")
    for i, name in enumerate(state.name):
        table.add_row(
            str(i),
            name,
            f"{state.position[i]:+.4f}",
            f"{state.target[i]:+.4f}",
            f"{state.velocity[i]:+.4f}",
            f"{state.effort[i]:+.2f}",
        )
    p, q = state.flange_position, state.flange_quaternion
    flange = Text(
        f"flange  xyz [{p[0]:+.4f} {p[1]:+.4f} {p[2]:+.4f}] m   "
        f"wxyz [{q[0]:+.4f} {q[1]:+.4f} {q[2]:+.4f} {q[3]:+.4f}]"
    )
    return Group(header, table, flange, Text(link, style="dim"))


def _link_text(status: ConnectionStatus) -> str:
    if status.connected:
        return f"connected: {status.detail}"
    retry = "" if status.retry_in is None else f"; retrying in {status.retry_in:.1f} s"
    return f"disconnected ({status.detail}){retry}"


def run_watch(url: str, world: int, rate: float | None = 10.0, as_json: bool = False) -> None:
    """Print world `world`'s stream until Ctrl-C: a live table, or JSON lines (`as_json`)."""
    client = ArmfleetClient(url)
    try:
        if as_json:
            _watch_json(client, world, rate)
        else:
            _watch_table(client, world, rate)
    except KeyboardInterrupt:
        pass
    except ArmfleetError as exc:
        print(f"armfleet watch: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    finally:
        client.close()


def _watch_json(client: ArmfleetClient, world: int, rate: float | None) -> None:
    def on_status(status: ConnectionStatus) -> None:
        print(f"armfleet watch: {_link_text(status)}", file=sys.stderr, flush=True)

    out = sys.stdout.buffer
    try:
        for state in client.stream(world, rate, on_status=on_status):
            out.write(orjson.dumps(state_json(state)) + b"\n")
            out.flush()
    except BrokenPipeError:
        # The reader went away (`| head`): leave without a traceback on the way out.
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def _watch_table(client: ArmfleetClient, world: int, rate: float | None) -> None:
    link = "connecting..."
    latest: WorldState | None = None

    def on_status(status: ConnectionStatus) -> None:
        nonlocal link
        link = _link_text(status)
        live.update(render(latest, client.url, world, link), refresh=True)

    with Live(render(None, client.url, world, link), console=Console(), auto_refresh=False) as live:
        for latest in client.stream(world, rate, on_status=on_status):
            live.update(render(latest, client.url, world, link), refresh=True)
