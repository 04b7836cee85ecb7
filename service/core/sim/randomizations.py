"""Which randomisation each world last had (seed and spec), by the tick it took effect at.

A snapshot names, per world, the last randomisation its state holds, or none: that is what
this book answers (`at(tick)`), on the sim thread where the state is taken. A randomisation is
recorded under the loop's command lock with the tick its reset is staged for (SimLoop.reset),
so a state of tick T names exactly the randomisations with tick <= T: one accepted but not yet
applied is not in that state and not in its header. A paused loop applies writes at once,
before their tick (StateDoor._settle): the entries it applied so are `held`, named at any tick
since. A restore replaces the book with what the snapshot names; a later plain reset or
entity write does not clear a world's entry (its worlds started from that draw; what came
after is in the state, and in a recording).

The wire form (snapshot headers, GET routes) groups worlds that share one randomisation:
[{"worlds": [0, 1, 2, 3], "tick": 12, "seed": 7, "spec": {...}}, ...].
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any


@dataclass(frozen=True)
class Randomized:
    """One randomisation of one world: the tick it took effect at, its seed and its spec."""

    tick: int
    seed: int
    spec: Mapping[str, Any]
    held: bool = field(default=False, compare=False)  # in the state before its tick (paused)

    def in_effect(self, tick: int) -> bool:
        """Does a state of `tick` hold it?"""
        return self.held or self.tick <= tick


class RandomizationBook:
    """Per world, the randomisations not yet superseded by a later one in effect (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._worlds: dict[int, list[Randomized]] = {}

    def record(self, worlds: Iterable[int], entry: Randomized, done_tick: int) -> None:
        """`entry` for `worlds`; entries older than the last one in effect at `done_tick` (the
        ticks completed) are forgotten: no state from now on can be before it."""
        with self._lock:
            for w in worlds:
                kept = [*self._worlds.get(int(w), ()), entry]
                live = [i for i, e in enumerate(kept) if e.in_effect(done_tick)]
                self._worlds[int(w)] = kept[live[-1] :] if live else kept

    def at(self, tick: int) -> dict[int, Randomized]:
        """The last randomisation in effect at `tick`, of each world that had one."""
        with self._lock:
            out = {}
            for w, entries in self._worlds.items():
                done = [e for e in entries if e.in_effect(tick)]
                if done:
                    out[w] = done[-1]
            return out

    def hold(self) -> None:
        """Every entry recorded so far is in the state now, whatever its tick (a paused loop
        applied the writes at once); older ones are forgotten as `record` does."""
        with self._lock:
            self._worlds = {
                w: [replace(entries[-1], held=True)] for w, entries in self._worlds.items()
            }

    def replace(self, worlds: Mapping[int, Randomized]) -> None:
        """Forget everything; hold `worlds` (a restored state's: in it, whatever their tick)."""
        with self._lock:
            self._worlds = {int(w): [replace(e, held=True)] for w, e in worlds.items()}


def groups(worlds: Mapping[int, Randomized]) -> list[dict[str, Any]]:
    """The wire form: one group per distinct randomisation, worlds ascending, groups by tick."""
    by: dict[tuple[int, int, str], list[int]] = {}
    for w in sorted(worlds):
        e = worlds[w]
        by.setdefault((e.tick, e.seed, json.dumps(e.spec, sort_keys=True)), []).append(w)
    return [
        {"worlds": ws, "tick": tick, "seed": seed, "spec": json.loads(spec)}
        for (tick, seed, spec), ws in sorted(by.items())
    ]


def from_groups(items: Sequence[Mapping[str, Any]] | None, nworld: int) -> dict[int, Randomized]:
    """Back from the wire form (a snapshot's header); ValueError naming what is wrong."""
    out: dict[int, Randomized] = {}
    for i, g in enumerate(items or ()):
        try:
            entry = Randomized(int(g["tick"]), int(g["seed"]), dict(g["spec"]))
            ids = [int(w) for w in g["worlds"]]
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"randomization.{i}: {type(exc).__name__}: {exc}") from None
        bad = [w for w in ids if not 0 <= w < nworld]
        if bad:
            raise ValueError(f"randomization.{i}: worlds {bad[:5]} outside 0..{nworld - 1}")
        out.update(dict.fromkeys(ids, entry))
    return out
