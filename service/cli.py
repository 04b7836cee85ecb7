"""`armfleet` command line: serve, setup (warm the kernel cache), controller, watch, bench,
capacity (how many worlds this machine holds), docs.

Heavy imports (warp, mujoco_warp, tkinter) happen inside each command so `armfleet --help`
is instant and `setup` can switch Warp's compile log on before Warp is imported.
"""

from __future__ import annotations

import inspect
import logging
import os
import socket
import time
import types
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin

import typer

from service.core.sim.types import Mode

# Nothing here renders with MuJoCo's OpenGL: without this, `import mujoco` loads GLFW (~0.1-0.3 s
# of every start). A value the user set wins.
os.environ.setdefault("MUJOCO_GL", "disable")

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Batched UR10e + 2F-140 simulation served over REST and WebSocket.",
)


def _opt(name: str) -> Any:
    """A `serve` option documented from its settings field (one description, one default);
    `name` is the field's flat name (service/settings.py: `flat_fields`).

    Options default to None so that only what the user typed overrides the settings, which
    themselves come from ARMFLEET_* variables or the field defaults.
    """
    from service.settings import flat_fields

    field = flat_fields()[name][2]
    default = field.default.value if isinstance(field.default, Mode) else field.default
    return typer.Option(
        help=f"{field.description or name} (default {default}; env ARMFLEET_{name.upper()})",
        show_default=False,
    )


def _check_port_free(host: str, port: int) -> None:
    """Fail before building anything when the port is taken: a server that cannot listen would
    otherwise still start, stop, and save its fresh state over snapshot `latest`."""
    if port == 0:
        return
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            typer.echo(f"armfleet serve: cannot listen on {host}:{port}: {exc}", err=True)
            raise typer.Exit(1) from None


def _cli_type(annotation: Any) -> Any:
    """The type a `serve` option parses to, from a Settings field's annotation: `X | None` is
    X, a Literal and a Path are typed as text (Settings checks them), the rest as they are."""
    if get_origin(annotation) in (Union, types.UnionType):
        return _cli_type(next(a for a in get_args(annotation) if a is not type(None)))
    if get_origin(annotation) is Literal or annotation is Path:
        return str
    return annotation


def _serve_signature(fn: Callable[..., None]) -> Callable[..., None]:
    """Give `serve` one option per settings field, by its flat name (`--worlds`,
    `--foxglove-port`, ...): the options are derived from the settings' sections, never listed
    again here, so a setting a surface adds is an option and an ARMFLEET_* variable at once."""
    from service.settings import flat_fields

    fn.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
        [
            inspect.Parameter(
                name,
                inspect.Parameter.KEYWORD_ONLY,
                default=None,
                annotation=Annotated[_cli_type(field.annotation) | None, _opt(name)],
            )
            for name, (_, _, field) in flat_fields().items()
        ]
    )
    return fn


@app.command()
@_serve_signature
def serve(**options: Any) -> None:
    """Start the service: N worlds, a real-time loop, REST + WebSocket on http://HOST:PORT.

    Bound to anything but loopback it needs --token (or ARMFLEET_TOKEN) unless --insecure.
    """
    given = {name: value for name, value in options.items() if value is not None}

    from service.app import create_app
    from service.core.errors import ArmfleetError
    from service.serving import serve_until_stopped
    from service.settings import Settings, flat_name

    try:
        settings = Settings(**given)
    except ValueError as exc:  # pydantic's ValidationError: each problem in words
        for err in exc.errors() if hasattr(exc, "errors") else [{"msg": str(exc), "loc": ()}]:
            where = flat_name(tuple(err["loc"]))  # the setting (ARMFLEET_<NAME>, --<name>)
            what = err["msg"].removeprefix("Value error, ")
            typer.echo(f"armfleet serve: {where + ': ' if where else ''}{what}", err=True)
        raise typer.Exit(2) from None
    _check_port_free(settings.server.host, settings.server.port)
    logging.basicConfig(
        level=settings.server.log_level.upper(), format="%(asctime)s %(name)s %(message)s"
    )
    try:
        service = create_app(settings)
    except (ValueError, ArmfleetError) as exc:  # an unsafe bind, a --record file not writable
        typer.echo(f"armfleet serve: {exc}", err=True)
        raise typer.Exit(2) from None
    problems = serve_until_stopped(service, service.state.runtime, settings)
    for problem in problems:
        typer.echo(f"armfleet serve: stopped, but {problem}", err=True)
    if problems:
        raise typer.Exit(1)


@app.command()
def replay(
    recording: Annotated[str, typer.Argument(help="an MCAP file written by --record")],
    out: Annotated[str | None, typer.Option(help="also write the replayed run here")] = None,
    device: Annotated[str, typer.Option(help="warp device to replay on (cpu, cuda)")] = "cpu",
    tolerance: Annotated[
        str,
        typer.Option(
            help="auto: bit for bit where the replay can be bit-exact (the CPU), else within "
            "the stated default; exact; or P,V,E: largest accepted |deviation| of position "
            "(rad), velocity (rad/s), effort (N·m)"
        ),
    ] = "auto",
    scene: Annotated[
        str | None, typer.Option(help="the cell the recording was made with (serve --scene)")
    ] = None,
) -> None:
    """Re-run a recording's commands at their ticks (fast) and compare every recorded state;
    exit 1 naming the first tick, world and joint that differ.

    Bit-exact only on the CPU (recorded and replayed there: Warp runs kernels serially). CUDA is
    not deterministic in MuJoCo Warp 4.0.0 (float atomics, contact order; its own switch does
    not help with contacts): a replay there compares within a tolerance that the report states,
    and grasps may go differently after a few seconds (README, "Replay on CUDA"). The largest
    deviation per tick range is printed either way.
    """
    logging.basicConfig(level="WARNING", format="%(asctime)s %(name)s %(message)s")
    from service.core.errors import ArmfleetError
    from service.persistence.replay import ReplayError
    from service.persistence.replay import replay as run_replay
    from service.persistence.replay_check import Tolerance, format_table

    try:
        judge = tolerance if tolerance in ("auto", "exact") else Tolerance.parse(tolerance)
        report = run_replay(recording, out, device, judge, scene)  # type: ignore[arg-type]
    except (ReplayError, ValueError, ArmfleetError) as exc:  # ArmfleetError: --out unwritable
        typer.echo(f"armfleet replay: {exc}", err=True)
        raise typer.Exit(2) from None
    if report.recorded_on != report.replayed_on:
        typer.echo(
            f"note: recorded on {report.recorded_on}, replayed on {report.replayed_on}; "
            "bit-identical results are only expected on the same device"
        )
    if report.truncated:
        typer.echo(f"note: the recording ends early ({report.truncated}); replayed what it holds")
    typer.echo(
        f"replayed {report.ticks} ticks of {report.nworld} worlds in {report.wall_s:.2f} s "
        f"({report.ticks_per_s:.0f} ticks/s): {report.commands} commands, "
        f"{report.restores} restores, {report.states_compared} recorded states compared"
        + (f"; wrote {report.out}" if report.out else "")
    )
    how = "bit for bit" if report.tolerance is None else f"within tolerance: {report.tolerance}"
    typer.echo(f"compared {how} (replayed on {report.replayed_on})")
    typer.echo(format_table(report.deviations))
    if report.divergence is not None:
        typer.echo(f"DIVERGED: {report.divergence}", err=True)
        raise typer.Exit(1)
    if report.tolerance is None:
        typer.echo("identical: every recorded state reproduced bit for bit")
    else:
        worst = ", ".join(f"{q} {v:.3g}" for q, v in report.largest.items())
        typer.echo(f"within tolerance: every recorded state reproduced (largest |Δ|: {worst})")


@app.command()
def setup(
    device: Annotated[str, typer.Option(help="device to compile for: cpu, cuda")] = "cpu",
) -> None:
    """Compile (or load from ~/.cache/warp) every kernel the service uses, showing progress:
    the engine's tick and the cameras' renderer (which a first start would otherwise compile
    beside its first ticks)."""
    os.environ["ARMFLEET_WARP_LOG"] = "info"
    typer.echo(
        f"armfleet setup: compiling MuJoCo Warp kernels for {device} "
        "(first time: about a minute on CPU, several on CUDA; cached afterwards)...",
    )
    t0 = time.perf_counter()
    from service.engines.warp import WorldBatch

    batch = WorldBatch(1, device=device)
    batch.step(2)
    from service.engines.camera_render import warm_renderer

    cameras, _ = warm_renderer(batch.robot.mjm, device)
    typer.echo(
        f"armfleet setup: ready in {time.perf_counter() - t0:.1f} s "
        f"(tick captured: {batch.captured}; {batch.substeps} substeps of "
        f"{batch.physics_dt * 1e3:.3f} ms per tick; {cameras} cameras drawn)"
    )


@app.command()
def controller(
    url: Annotated[str, typer.Option(help="service base URL")] = "http://127.0.0.1:8000",
    world: Annotated[int, typer.Option(help="world to drive")] = 0,
    terminal: Annotated[bool, typer.Option(help="terminal UI instead of a Tk window")] = False,
    token: Annotated[
        str | None,
        typer.Option(help="the service's token (env ARMFLEET_TOKEN)", envvar="ARMFLEET_TOKEN"),
    ] = None,
    lease: Annotated[
        bool, typer.Option(help="take a free world while the controller runs; give it back on exit")
    ] = False,
    lease_token: Annotated[
        str | None, typer.Option(help="drive the world of a lease you were handed")
    ] = None,
) -> None:
    """The seed's button controller: seven joints, Up (+0.1) / Down (-0.1)."""
    from clients.apps.lease_session import session_world
    from clients.errors import ArmfleetError

    try:
        with session_world(url, token, world, lease, lease_token) as (world, token):
            if lease or lease_token:
                typer.echo(f"armfleet controller: driving world {world} (leased)", err=True)
            if terminal:
                from clients.apps.tui import run_tui

                run_tui(url=url, world=world, token=token)
            else:
                from clients.apps.tk_controller import run_tk

                run_tk(url=url, world=world, token=token)
    except ArmfleetError as exc:  # no world free, a wrong token, an ended lease
        typer.echo(f"armfleet controller: {exc}", err=True)
        raise typer.Exit(1) from None


@app.command()
def watch(
    url: Annotated[str, typer.Option(help="service base URL")] = "http://127.0.0.1:8000",
    world: Annotated[int, typer.Option(help="world to watch")] = 0,
    rate: Annotated[float, typer.Option(help="frames per second")] = 10.0,
    json: Annotated[bool, typer.Option("--json", help="one JSON line per frame")] = False,
) -> None:
    """Print a world's state stream as a live table (or JSON lines for piping)."""
    from clients.apps.watch import run_watch

    run_watch(url=url, world=world, rate=rate, as_json=json)


@app.command()
def bench(
    section: Annotated[
        list[int] | None, typer.Option(help="run this section (repeatable; --list shows them)")
    ] = None,
    quick: Annotated[bool, typer.Option(help="smaller sizes and shorter runs")] = False,
    device: Annotated[str, typer.Option(help="cpu or cuda[:N]")] = "cpu",
    worlds: Annotated[
        list[int] | None, typer.Option(help="batch size instead of the sections' (repeatable)")
    ] = None,
    out: Annotated[Path | None, typer.Option(help="results folder (default bench/results)")] = None,
    list_: Annotated[bool, typer.Option("--list", help="list the sections and exit")] = False,
) -> None:
    """Benchmarks against native MuJoCo and raw MuJoCo Warp; writes bench/results/."""
    from bench import registry, runner

    if list_:
        print(runner.listing(registry.discover()))
        return
    report = runner.run(section or None, quick, device, worlds or None, out)
    if report["errors"]:
        raise typer.Exit(1)


@app.command()
def capacity(
    engine: Annotated[
        list[str] | None,
        typer.Option(help="mujoco, warp or warp_cuda (repeatable; default: every one here)"),
    ] = None,
    quick: Annotated[bool, typer.Option(help="short windows: a first look in ~30 s")] = False,
    check: Annotated[
        bool, typer.Option(help="then run each answer again for 10 s (RTF >= 0.99)")
    ] = False,
    out: Annotated[
        Path | None, typer.Option(help="JSON file (default bench/results/capacity.json)")
    ] = None,
    worlds: Annotated[
        int | None, typer.Option(help="fast-mode probe size instead of a share of the limit")
    ] = None,
    max_worlds: Annotated[int | None, typer.Option(help="never try more worlds than this")] = None,
) -> None:
    """How many worlds this machine holds in real time, per engine, in about a minute: the
    raw rollout limit, and each engine's worlds with a 30 Hz subscriber of every world, as a
    number and a ratio to the limit. Exit 1 when an engine holds none or misses its check."""
    from bench import how_many

    try:
        ask = how_many.Ask(engine or None, quick, check, worlds, max_worlds)
        result = how_many.run(ask, out)
    except ValueError as exc:  # an unknown engine
        typer.echo(f"armfleet capacity: {exc}", err=True)
        raise typer.Exit(2) from None
    if not how_many.held_everywhere(result):
        raise typer.Exit(1)


@app.command()
def docs(
    port: Annotated[int, typer.Option(help="port on 127.0.0.1 to serve the site on")] = 8001,
    build: Annotated[bool, typer.Option("--build", help="only build the site, then exit")] = False,
    out: Annotated[Path | None, typer.Option(help="with --build: where (default site/)")] = None,
) -> None:
    """Build the documentation site (docs/, mkdocs.yml) and serve it on 127.0.0.1 to read
    locally; its reference pages are generated from this code as it builds."""
    import importlib.util
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    config = root / "mkdocs.yml"
    if not config.exists():
        typer.echo("armfleet docs: the site's sources come with a source checkout", err=True)
        raise typer.Exit(1)
    if importlib.util.find_spec("mkdocs") is None:
        typer.echo("armfleet docs: install the doc tools: pip install -e '.[docs]'", err=True)
        raise typer.Exit(1)
    mkdocs = [sys.executable, "-m", "mkdocs"]
    if build:
        site = out or root / "site"
        command = [*mkdocs, "build", "--strict", "-f", str(config), "-d", str(site)]
    else:
        typer.echo(f"armfleet docs: http://127.0.0.1:{port}/ (Ctrl-C stops)")
        command = [*mkdocs, "serve", "-f", str(config), "-a", f"127.0.0.1:{port}"]
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    if build:
        raise typer.Exit(subprocess.run(command, cwd=root, env=env).returncode)
    # mkdocs takes this process's place: a signal sent to it (a supervisor's SIGTERM, a test's
    # SIGINT) reaches the server itself, not a parent that would leave it running orphaned
    os.chdir(root)
    os.execve(sys.executable, command, env)


if __name__ == "__main__":
    app()
