"""`armfleet` command line: serve, setup (warm the kernel cache), controller, watch, bench.

Heavy imports (warp, mujoco_warp, tkinter) happen inside each command so `armfleet --help`
is instant and `setup` can switch Warp's compile log on before Warp is imported.
"""

from __future__ import annotations

import logging
import os
import time
from typing import Annotated

import typer

from service.types import Mode

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Batched UR10e + 2F-140 simulation served over REST and WebSocket.",
)


@app.command()
def serve(
    worlds: Annotated[int, typer.Option(help="parallel worlds")] = 16,
    device: Annotated[str, typer.Option(help="warp device: cpu, cuda or cuda:N")] = "cpu",
    host: Annotated[str, typer.Option(help="bind address")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port")] = 8000,
    mode: Annotated[Mode, typer.Option(help="how time advances")] = Mode.REALTIME,
    shards: Annotated[int, typer.Option(help="CPU processes sharing the worlds; 0 = auto")] = 0,
    ray: Annotated[
        str | None,
        typer.Option(help="shards on Ray actors: auto, local or HOST:PORT (a head node)"),
    ] = None,
    control_hz: Annotated[float, typer.Option(help="control ticks per second")] = 60.0,
    physics_dt: Annotated[float, typer.Option(help="approximate physics step [s]")] = 0.002,
    log_level: Annotated[str, typer.Option(help="debug, info, warning, error")] = "info",
) -> None:
    """Start the service: N worlds, a real-time loop, REST + WebSocket on http://HOST:PORT."""
    import uvicorn

    from service.app import create_app
    from service.settings import Settings

    settings = Settings(
        worlds=worlds,
        device=device,
        host=host,
        port=port,
        mode=mode,
        shards=shards,
        ray=ray,
        control_hz=control_hz,
        physics_dt=physics_dt,
        log_level=log_level,
    )
    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(name)s %(message)s")
    uvicorn.run(
        create_app(settings),
        host=host,
        port=port,
        log_level=log_level,
        ws_max_size=1 << 20,
        timeout_graceful_shutdown=3,
    )


@app.command()
def setup(
    device: Annotated[str, typer.Option(help="device to compile for: cpu, cuda")] = "cpu",
) -> None:
    """Compile (or load from ~/.cache/warp) every kernel the service uses, showing progress."""
    os.environ["ARMFLEET_WARP_LOG"] = "info"
    typer.echo(
        f"armfleet setup: compiling MuJoCo Warp kernels for {device} "
        "(first time: about a minute on CPU, several on CUDA; cached afterwards)...",
    )
    t0 = time.perf_counter()
    from service.engine import WorldBatch

    batch = WorldBatch(1, device=device)
    batch.step(2)
    typer.echo(
        f"armfleet setup: ready in {time.perf_counter() - t0:.1f} s "
        f"(tick captured: {batch.captured}; {batch.substeps} substeps of "
        f"{batch.physics_dt * 1e3:.3f} ms per tick)"
    )


@app.command()
def controller(
    url: Annotated[str, typer.Option(help="service base URL")] = "http://127.0.0.1:8000",
    world: Annotated[int, typer.Option(help="world to drive")] = 0,
    terminal: Annotated[bool, typer.Option(help="terminal UI instead of a Tk window")] = False,
) -> None:
    """The seed's button controller: seven joints, Up (+0.1) / Down (-0.1)."""
    if terminal:
        from clients.tui import run_tui

        run_tui(url=url, world=world)
    else:
        from clients.tk_controller import run_tk

        run_tk(url=url, world=world)


@app.command()
def watch(
    url: Annotated[str, typer.Option(help="service base URL")] = "http://127.0.0.1:8000",
    world: Annotated[int, typer.Option(help="world to watch")] = 0,
    rate: Annotated[float, typer.Option(help="frames per second")] = 10.0,
    json: Annotated[bool, typer.Option("--json", help="one JSON line per frame")] = False,
) -> None:
    """Print a world's state stream as a live table (or JSON lines for piping)."""
    from clients.watch import run_watch

    run_watch(url=url, world=world, rate=rate, as_json=json)


@app.command()
def bench(
    quick: Annotated[bool, typer.Option(help="smaller sizes and shorter runs")] = False,
    device: Annotated[str, typer.Option(help="cpu or cuda")] = "cpu",
    sections: Annotated[
        list[int] | None, typer.Option("--section", help="run only these (1-6); repeatable")
    ] = None,
) -> None:
    """Benchmarks against native MuJoCo and raw MuJoCo Warp; writes bench/results/."""
    from bench.suite import run_suite

    run_suite(quick=quick, device=device, sections=sections or None)


if __name__ == "__main__":
    app()
