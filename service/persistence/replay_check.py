"""How a replay judges the states it reproduces: bit for bit, or within a stated tolerance.

On the CPU Warp runs every kernel on one thread, so the same state and commands give the same
bits and a replay there must reproduce every recorded number exactly. On CUDA, MuJoCo Warp 4.0.0
is not deterministic (measured on an H100, bench/replay_cuda.py): float atomics sum in varying
order, and contacts and constraint rows take their slots from counters shared by all worlds, so
they come in varying order. Its own switch (`opt.deterministic`) only orders the atomics: its
CONTACTS and CONSTRAINT bits are accepted but not implemented, and runs still differ from the
first tick. Warp's process-wide RUN_TO_RUN mode (which would also order counter slots) stops at
the first step: MuJoCo Warp's convex collision kernel cannot be run that way. So off the CPU the
replay accepts deviations up to a stated tolerance, and either way keeps the largest deviation of
each quantity per range of ticks: over a grasp, two CUDA runs stay within ~2e-4 rad for a few
seconds and then a grasp can go differently (the finger ends 0.24 rad apart).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

QUANTITIES = ("position", "velocity", "effort")
UNITS = {"position": "rad", "velocity": "rad/s", "effort": "N·m"}


@dataclass(frozen=True)
class Tolerance:
    """Largest accepted |replayed - recorded| per quantity (absolute, in the quantity's unit)."""

    position: float
    velocity: float
    effort: float

    def of(self, quantity: str) -> float:
        return float(getattr(self, quantity))

    def __str__(self) -> str:
        return ", ".join(f"|Δ{q}| ≤ {self.of(q):g} {UNITS[q]}" for q in QUANTITIES)

    @classmethod
    def parse(cls, text: str) -> Tolerance:
        """'P,V,E' (three numbers) or one number for all three; ValueError naming the problem."""
        parts = [p.strip() for p in text.split(",")]
        if len(parts) == 1:
            parts *= 3
        if len(parts) != 3:
            raise ValueError(
                f"tolerance {text!r}: give one number or three (position,velocity,effort)"
            )
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise ValueError(f"tolerance {text!r}: not a number") from None
        if not all(math.isfinite(v) and v >= 0 for v in values):
            raise ValueError(f"tolerance {text!r}: each value must be finite and >= 0")
        return cls(*values)


# Accepted where the replay cannot be bit-exact: about 4x the largest deviations of two H100 runs
# of the same grasp commands over their first 240 ticks (2.4e-4 rad, 1.3e-2 rad/s, 0.30 N·m;
# bench/results/replay_cuda.json), so float noise passes and a grasp that went otherwise fails.
TOLERANCE = Tolerance(position=1e-3, velocity=5e-2, effort=1.0)


def bit_exact(device: str) -> bool:
    """Whether two runs of the same commands from the same state give the same bits on `device`
    (a batch's device name: "cpu", "cuda:0", ...): on the CPU only, see the module doc."""
    return str(device).startswith("cpu")


@dataclass(frozen=True)
class Divergence:
    """The first recorded number the replay did not reproduce (exactly, or within tolerance)."""

    tick: int
    world: int
    joint: str
    quantity: str
    recorded: float
    replayed: float

    def __str__(self) -> str:
        return (
            f"diverged at tick {self.tick}, world {self.world}, joint {self.joint} "
            f"({self.quantity}): recorded {self.recorded!r}, replayed {self.replayed!r}"
        )


@dataclass
class DeviationRange:
    """The largest |replayed - recorded| of each quantity over ticks first..last (the range's
    first tick and the last tick compared in it)."""

    first: int
    last: int
    states: int = 0
    largest: dict[str, float] = field(default_factory=lambda: dict.fromkeys(QUANTITIES, 0.0))
    # where the largest position deviation was: (tick, world, joint)
    where: tuple[int, int, str] | None = None

    def as_dict(self) -> dict[str, object]:
        return {
            "first_tick": self.first,
            "last_tick": self.last,
            "states": self.states,
            **{f"max_abs_{q}": self.largest[q] for q in QUANTITIES},
            "worst_position_at": self.where,
        }


class Comparison:
    """Compares replayed states with the recorded ones; `tolerance` None means bit for bit.

    `span`: ticks per row of the deviation table.
    """

    def __init__(self, names: list[str], tolerance: Tolerance | None, span: int) -> None:
        self.names = names
        self.tolerance = tolerance
        self.span = max(1, int(span))
        self.divergence: Divergence | None = None
        self.ranges: dict[int, DeviationRange] = {}

    @property
    def exact(self) -> bool:
        return self.tolerance is None

    def check(
        self, tick: int, worlds: np.ndarray, recorded: np.ndarray, replayed: np.ndarray
    ) -> None:
        """Compare the recorded worlds' states at one tick, all at once (k worlds: `recorded`
        and `replayed` are (k, 3, njoint): position, velocity, effort); remembers the first
        divergence (in world, quantity, joint order)."""
        key = (tick - 1) // self.span
        row = self.ranges.get(key)
        if row is None:
            row = self.ranges[key] = DeviationRange(key * self.span + 1, tick)
        row.last = max(row.last, tick)
        row.states += len(worlds)
        dev = np.abs(replayed - recorded)
        dev[np.isnan(dev)] = np.inf  # NaN on one side only is as far off as it gets
        dev[replayed == recorded] = 0.0  # equal infinities
        for q, quantity in enumerate(QUANTITIES):
            k, j = np.unravel_index(int(np.argmax(dev[:, q])), dev[:, q].shape)
            if dev[k, q, j] > row.largest[quantity]:
                row.largest[quantity] = float(dev[k, q, j])
                if quantity == "position":
                    row.where = (tick, int(worlds[k]), self.names[j])
        if self.divergence is not None:
            return
        if self.tolerance is None:
            bad = np.argwhere(replayed != recorded)
        else:
            limits = np.array([self.tolerance.of(q) for q in QUANTITIES])
            bad = np.argwhere(dev > limits[None, :, None])
        if bad.size:
            k, q, j = (int(x) for x in bad[0])
            self.divergence = Divergence(
                tick,
                int(worlds[k]),
                self.names[j],
                QUANTITIES[q],
                float(recorded[k, q, j]),
                float(replayed[k, q, j]),
            )

    def rows(self) -> list[DeviationRange]:
        """The deviation table, in tick order (only ranges with recorded states)."""
        return [self.ranges[k] for k in sorted(self.ranges)]

    def largest(self) -> dict[str, float]:
        """The largest deviation of each quantity over the whole replay."""
        return {
            q: max((r.largest[q] for r in self.ranges.values()), default=0.0) for q in QUANTITIES
        }


def table_span(first_tick: int, last_tick: int, rows: int = 10, multiple: int = 60) -> int:
    """Ticks per table row: about `rows` rows, each a whole number of `multiple` ticks."""
    ticks = max(1, last_tick - first_tick)
    return max(multiple, math.ceil(ticks / rows / multiple) * multiple)


def format_table(rows: list[DeviationRange]) -> str:
    """The deviation table as the CLI prints it."""
    head = f"{'ticks':>13} {'states':>7}" + "".join(
        f" {'max |Δ' + q + '| ' + UNITS[q]:>24}" for q in QUANTITIES
    )
    lines = [head]
    for r in rows:
        cells = "".join(f" {r.largest[q]:>24.3e}" for q in QUANTITIES)
        lines.append(f"{f'{r.first}-{r.last}':>13} {r.states:>7}{cells}")
    return "\n".join(lines)
