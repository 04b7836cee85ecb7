"""Joint-target arithmetic shared by the target commands: increments and absolute targets,
clamped to the joint ranges.

Pure functions over one world's target row so that the loop can apply them under its lock and
the tests can pin the arithmetic without a simulator.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from service.core.errors import BadCommand
from service.core.sim.types import RobotSpec

MAX_ABS_DELTA = 2 * math.pi  # one press may not move a target by more than a full turn
# Increments are rounded to this many decimals so that repeated ±0.1 presses land on decimal
# values (0.1 * 7 == 0.7 exactly, and back down to exactly 0.0), as the seed's round(x, 2) did.
_INCREMENT_DECIMALS = 9


@dataclass(frozen=True)
class TargetUpdate:
    """One world's new target row and the joints that were clamped at a range limit."""

    target: np.ndarray
    clamped: list[str]


def resolve_joints(
    spec: RobotSpec, values: Mapping[str | int, float], field: str
) -> dict[int, float]:
    """Map joint names or indices to indices, checking every value is a finite number."""
    if not values:
        raise BadCommand(field, f"{field} must name at least one joint")
    out: dict[int, float] = {}
    for key, value in values.items():
        try:
            idx = spec.index(int(key) if isinstance(key, str) and key.isdigit() else key)
        except KeyError as exc:
            raise BadCommand(f"{field}.{key}", exc.args[0]) from None
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise BadCommand(f"{field}.{key}", f"value must be a number, got {value!r}")
        if not math.isfinite(value):
            raise BadCommand(f"{field}.{key}", "value must be finite (no NaN or Inf)")
        out[idx] = float(value)
    return out


def _clamp(spec: RobotSpec, row: np.ndarray, touched: list[int]) -> TargetUpdate:
    lower, upper = spec.lower, spec.upper
    clamped = [spec.joints[i].name for i in touched if row[i] < lower[i] or row[i] > upper[i]]
    return TargetUpdate(target=np.clip(row, lower, upper), clamped=clamped)


def check_deltas(spec: RobotSpec, deltas: Mapping[int, float]) -> None:
    """One press may move a target by at most a full turn (checked when a command is made)."""
    for i, delta in deltas.items():
        if abs(delta) > MAX_ABS_DELTA:
            name = spec.joints[i].name
            raise BadCommand(f"delta.{name}", f"|delta| must be <= 2π ({MAX_ABS_DELTA:.6f} rad)")


def increment(spec: RobotSpec, current: np.ndarray, deltas: Mapping[int, float]) -> TargetUpdate:
    """Add `deltas` (joint index → rad, checked by `check_deltas`) to `current` and clamp."""
    row = np.array(current, dtype=np.float64)
    for i, delta in deltas.items():
        row[i] = round(row[i] + delta, _INCREMENT_DECIMALS)
    return _clamp(spec, row, list(deltas))


def replace_targets(
    spec: RobotSpec, current: np.ndarray, values: Mapping[int, float]
) -> TargetUpdate:
    """Replace the named joints' targets (others keep theirs) and clamp to range."""
    row = np.array(current, dtype=np.float64)
    for i, value in values.items():
        row[i] = value
    return _clamp(spec, row, list(values))
