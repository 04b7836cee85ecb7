"""The bench's sections: what one is, how it is registered, and what it is given.

Adding a section is one decorated function in its own module under ``bench/``::

    from bench.registry import Context, Result, section

    @section(8, "ros_roundtrip")
    def ros_roundtrip(ctx: Context) -> Result:
        '''ROS 2 command → state round trip'''

        def one(n: int) -> dict:
            with ctx.serve(n) as srv:               # clients.testing.serve, on ctx.device
                return {"nworld": n, "p50_ms": ...}  # measure against srv.url / srv.ws_url

        results, errors = ctx.each(ctx.sizes((16, 64), quick=(16,)), one, lambda r: "...")
        rows = [{"worlds": int(n), "p50 ms": r["p50_ms"]} for n, r in results.items()]
        return Result.per_size(rows, results, errors)

    if __name__ == "__main__":
        from bench.runner import main

        raise SystemExit(main(module=__name__))

* The number orders the sections and is what ``--section N`` takes; the name is the results file
  stem (``bench/results/<name>.json``, ``<name>_cuda.json`` for ``--device cuda``): keep both
  stable once results exist. ``armfleet bench --list`` shows the numbers taken; registering a
  number or name twice fails at import.
* The title (``--list``, the printed report, the results file) is the first paragraph of the
  function's docstring.
* ``devices`` says where the section can run (``cpu``, ``cuda``); ``default_on`` where it runs
  when no ``--section`` is given (default: everywhere it can run).
* ``rows`` become the printed table (one dict a row, keys are the column headings, values raw
  numbers or short strings); ``data`` is the JSON's detail; ``notes`` are printed under the table.
  Record failures in ``data["errors"]`` rather than raising: the runner prints them, and a section
  that raises is recorded as failed while the others still run.
* Modules under ``bench/`` are imported to find sections (bench.runner does it), so they must stay
  light at import: import Warp, MuJoCo and other heavy packages inside functions.
"""

from __future__ import annotations

import contextlib
import inspect
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench import common


@dataclass
class Result:
    """What a section returns."""

    rows: list[dict[str, Any]]  # the table, one dict a row (keys: column headings)
    data: dict[str, Any] = field(default_factory=dict)  # the JSON's detail
    notes: list[str] = field(default_factory=list)  # printed under the table

    @classmethod
    def per_size(
        cls,
        rows: list[dict[str, Any]],
        results: Mapping[str, Any],
        errors: Mapping[str, str],
        detail: Mapping[str, Any] | None = None,
        notes: Sequence[str] = (),
    ) -> Result:
        """A section measured size by size (`Context.each`): the JSON's detail is `detail`, then
        every size's result and every size's failure (`errors`, which the runner reports)."""
        return cls(rows, {**(detail or {}), "results": results, "errors": errors}, list(notes))


@dataclass
class Context:
    """What every section is given: the run's options, where results go, earlier sections."""

    quick: bool = False  # smaller sizes, shorter windows (a few minutes for everything)
    device: str = "cpu"  # Warp device of the engine / the served worlds: cpu, cuda, cuda:N
    out_dir: Path = common.RESULTS_DIR
    worlds: Sequence[int] | None = None  # --worlds: batch sizes that replace the section's own
    say: Callable[[str], None] = print  # progress lines
    done: dict[str, dict[str, Any]] = field(default_factory=dict)  # payloads of this run, by name

    @property
    def cuda(self) -> bool:
        return self.device.startswith("cuda")

    @property
    def suffix(self) -> str:
        return common.suffix_for(self.device)

    def sizes(self, full: Sequence[int], quick: Sequence[int] | None = None) -> list[int]:
        """The batch sizes to measure: --worlds when given, else `quick` or `full`."""
        if self.worlds:
            return list(self.worlds)
        return list(quick if self.quick and quick is not None else full)

    def pick(self, full: Any, quick: Any) -> Any:
        return quick if self.quick else full

    def earlier(self, name: str) -> dict[str, Any] | None:
        """Another section's payload: from this run, else its last results file for this device."""
        return self.done.get(name) or common.read_json(f"{name}{self.suffix}.json", self.out_dir)

    def serve(
        self, worlds: int, mode: str = "realtime", env: Mapping[str, str] | None = None
    ) -> contextlib.AbstractContextManager[common.Served]:
        """`armfleet serve` on this run's device, stopped when the block ends."""
        return common.served(worlds, mode, self.device, env)

    def each(
        self,
        sizes: Sequence[int],
        measure: Callable[[int], dict[str, Any]],
        describe: Callable[[dict[str, Any]], str],
    ) -> tuple[dict[str, dict[str, Any]], dict[str, str]]:
        """`measure(n)` at every size: ({"n": result}, {"n": error}); one failure loses one size."""
        results: dict[str, dict[str, Any]] = {}
        errors: dict[str, str] = {}
        for n in sizes:
            t0 = time.perf_counter()
            try:
                results[str(n)] = res = measure(n)
            except Exception as exc:
                errors[str(n)] = f"{type(exc).__name__}: {exc}"
                self.say(f"  {n:>6} worlds  FAILED: {errors[str(n)]}")
                continue
            self.say(f"  {n:>6} worlds  {describe(res)}  ({time.perf_counter() - t0:.1f} s)")
        return results, errors


SectionFn = Callable[[Context], Result]


@dataclass(frozen=True)
class Section:
    number: int
    name: str  # results file stem
    title: str
    fn: SectionFn
    devices: tuple[str, ...]
    default_on: tuple[str, ...]
    module: str

    def runs_on(self, device: str) -> bool:
        return device_kind(device) in self.devices


SECTIONS: dict[int, Section] = {}


def device_kind(device: str) -> str:
    """'cuda:1' → 'cuda'."""
    return device.split(":", 1)[0]


def section(
    number: int,
    name: str,
    devices: Sequence[str] = ("cpu",),
    default_on: Sequence[str] | None = None,
) -> Callable[[SectionFn], SectionFn]:
    """Register `fn` as section `number`, written to bench/results/`name`[_cuda].json; its
    title is the first paragraph of its docstring."""

    def register(fn: SectionFn) -> SectionFn:
        # `python -m bench.x`: the runner imports it as bench.x; a process it spawns imports the
        # main module again as __mp_main__ (section 30's clients failed on a second section 30)
        if fn.__module__ in ("__main__", "__mp_main__"):
            return fn
        taken = SECTIONS.get(number)
        if taken is not None and (taken.module, taken.fn.__name__) != (fn.__module__, fn.__name__):
            raise ValueError(f"bench section {number} is taken by {taken.module}.{taken.name}")
        if any(s.name == name and s.number != number for s in SECTIONS.values()):
            raise ValueError(f"bench section name {name!r} is taken")
        SECTIONS[number] = Section(
            number,
            name,
            " ".join(inspect.getdoc(fn).split("\n\n")[0].split()) if fn.__doc__ else name,
            fn,
            tuple(devices),
            tuple(devices if default_on is None else default_on),
            fn.__module__,
        )
        return fn

    return register


def discover() -> dict[int, Section]:
    """Import every module of the bench package, so that their sections register; by number."""
    import importlib
    import pkgutil

    import bench

    for mod in pkgutil.iter_modules(bench.__path__):
        if mod.name not in {"registry", "runner", "common", "plot", "__main__"}:
            importlib.import_module(f"bench.{mod.name}")
    return dict(sorted(SECTIONS.items()))
