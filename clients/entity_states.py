"""Entities in a state (`entities=True`): each named free body's pose and twist, at the tick of
the joints they come with.

A batch frame holds them column-wise, like its joints (axis 0 the frame's worlds, axis 1 the
entities in `name` order); one world's state holds them without the world axis. Arrays are
numpy float64. Orientation is a quaternion w x y z; `linear` is in the world frame [m/s],
`angular` in the body's own frame [rad/s] (MuJoCo's free joint).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

_FIELDS = (("position", 3), ("orientation", 4), ("linear", 3), ("angular", 3))


@dataclass(frozen=True, eq=False)
class EntityStates:
    """Entities of one world ((ne, k) arrays) or of a batch's worlds ((n, ne, k) arrays)."""

    name: tuple[str, ...]
    position: np.ndarray  # x y z [m], world frame
    orientation: np.ndarray  # w x y z
    linear: np.ndarray  # [m/s], world frame
    angular: np.ndarray  # [rad/s], body frame

    def index(self, name: str) -> int:
        if name not in self.name:
            raise KeyError(f"no entity {name!r}; entities are {list(self.name)}")
        return self.name.index(name)

    def row(self, i: int) -> EntityStates:
        """Row i of a batch's entities: one world's."""
        arrays = {k: getattr(self, k)[i] for k, _ in _FIELDS}
        return EntityStates(name=self.name, **arrays)

    @classmethod
    def from_columns(cls, d: Mapping[str, Any], n: int) -> EntityStates:
        """A batch frame's `entities` (`name`, then (n, ne, k) nested lists)."""
        names = tuple(d["name"])
        arrays = {
            k: np.array(d[k], dtype=np.float64).reshape(n, len(names), width)
            for k, width in _FIELDS
        }
        return cls(name=names, **arrays)

    @classmethod
    def from_block(cls, header: Mapping[str, Any], data: bytes, at: int, n: int) -> EntityStates:
        """A binary frame's entity block: float32[n, ne, width] at byte `at` of `data`,
        `header` its {"name", "columns"} (layout in service/core/streams/wire.py)."""
        names = tuple(header["name"])
        width = sum(w for _, w in header["columns"])
        block = np.frombuffer(data, "<f4", n * len(names) * width, at)
        block = block.reshape(n, len(names), width).astype(np.float64)
        arrays, col = {}, 0
        for name, w in header["columns"]:
            arrays[name] = block[:, :, col : col + w]
            col += w
        return cls(name=names, **{k: arrays[k] for k, _ in _FIELDS})

    @classmethod
    def from_list(cls, items: Sequence[Mapping[str, Any]]) -> EntityStates:
        """One world's `entities` (a list of {name, position, orientation, linear, angular})."""
        arrays = {
            k: np.array([e[k] for e in items], dtype=np.float64).reshape(len(items), width)
            for k, width in _FIELDS
        }
        return cls(name=tuple(e["name"] for e in items), **arrays)

    @classmethod
    def stack(cls, worlds: Sequence[EntityStates]) -> EntityStates:
        """One world's entities each → a batch's (the worlds share the scene's entities)."""
        names = worlds[0].name if worlds else ()
        arrays = {
            k: np.array([getattr(w, k) for w in worlds], dtype=np.float64).reshape(
                len(worlds), len(names), width
            )
            for k, width in _FIELDS
        }
        return cls(name=names, **arrays)
