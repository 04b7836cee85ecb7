"""Entities in state frames (`entities=true`): what a frame costs with them, against without.

Per engine (native MuJoCo, MuJoCo Warp on this run's device) and batch size, one frame of every
world as the service makes it, in its two halves: on the sim thread, `frames.pack` of the
rows (plus, with entities, `entity_frames.read` of the same tick); then, on the frame thread,
the JSON and the binary serialisation (plus the entity block). The two variants alternate in
windows on one batch, and each ratio (with / without) is the median over pairs of neighbouring
windows, so a box that slows down slows both. A subscriber that does not ask pays nothing:
its frames are the bytes of before (tests/test_entity_frames.py).

Section 27 of ``armfleet bench`` (``--section 27``), or ``python -m bench.entity_frames_bench``.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

from bench.registry import Context, Result, section


def _build(engine: str, n: int, device: str) -> Any:
    if engine == "native":
        from service.engines.native import NativeBatch

        return NativeBatch(n)
    from service.engines.warp import WorldBatch

    return WorldBatch(n, device=device)


def _frame(batch: Any, ids: np.ndarray, entities: bool) -> tuple[float, float, float]:
    """One frame of `ids`: seconds on the sim thread, for JSON and for binary serialisation."""
    from service.core.streams import entity_frames, frames

    t0 = time.perf_counter()
    data = frames.pack(batch, ids, json=True)
    assert data is not None
    if entities:
        data.entities = entity_frames.read(batch, ids)
    rows = data.packed.wait()
    t1 = time.perf_counter()
    try:
        names = batch.spec.names
        (frames.json_entities if entities else frames.json)(data, rows, names)
        t2 = time.perf_counter()
        (frames.binary_entities if entities else frames.binary)(data, rows, names)
        t3 = time.perf_counter()
    finally:
        data.packed.release()
    return t1 - t0, t2 - t1, t3 - t2


def measure(engine: str, n: int, device: str, windows: int, frames_per: int) -> dict[str, Any]:
    batch = _build(engine, n, device)
    try:
        batch.step(2)
        ids = np.arange(n)
        for flag in (False, True):
            _frame(batch, ids, flag)  # warm
        spent: dict[bool, list[np.ndarray]] = {False: [], True: []}
        for _ in range(windows):
            for flag in (False, True):
                times = [_frame(batch, ids, flag) for _ in range(frames_per)]
                spent[flag].append(np.median(np.array(times), axis=0))
                batch.step(1)
        out: dict[str, Any] = {"engine": engine, "worlds": n}
        for i, part in enumerate(("sim_thread", "json", "binary")):
            plain = [w[i] for w in spent[False]]
            asked = [w[i] for w in spent[True]]
            out[part] = {
                "without_ms": round(statistics.median(plain) * 1000, 3),
                "with_ms": round(statistics.median(asked) * 1000, 3),
                "ratio": round(
                    statistics.median(a / p for a, p in zip(asked, plain, strict=True)), 2
                ),
            }
        return out
    finally:
        batch.close()


@section(27, "entity_frames")
def entity_frames_section(ctx: Context) -> Result:
    """Entities in state frames: one frame with them vs without"""
    sizes = ctx.sizes((256, 4096), (256, 1024))
    windows, frames_per = ctx.pick((8, 5), (4, 3))
    rows, data = [], {"runs": [], "errors": {}}
    for engine in ("native", "warp"):
        for n in sizes:
            try:
                r = measure(engine, n, ctx.device, windows, frames_per)
            except Exception as exc:  # one failure loses one size
                data["errors"][f"{engine} {n}"] = f"{type(exc).__name__}: {exc}"
                continue
            data["runs"].append(r)
            for part in ("sim_thread", "json", "binary"):
                p = r[part]
                rows.append(
                    {
                        "measure": f"{engine}, {n} worlds, {part.replace('_', ' ')}",
                        "without entities": f"{p['without_ms']} ms",
                        "with entities": f"{p['with_ms']} ms",
                        "ratio": p["ratio"],
                    }
                )
            ctx.say(
                f"  {engine} {n}: "
                + ", ".join(f"{k} {r[k]['ratio']}" for k in ("sim_thread", "json", "binary"))
            )
    notes = [
        "ratio: with entities / without, the median over pairs of neighbouring windows; the "
        "default scene has one entity (the cube); sim thread: pack (+ entity read), JSON and "
        "binary: serialising one frame of every world on the frame thread"
    ]
    return Result(rows, data=data, notes=notes)


if __name__ == "__main__":
    from bench.runner import main

    raise SystemExit(main(module=__name__))
