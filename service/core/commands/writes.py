"""What the commands that write engine state of many worlds at one tick boundary share
(`set_entity`, `set_params`): how many writes one may carry, the example of their batch body,
and `ManyWrites`, whose writes are staged together, announced with the worlds they changed and
recorded as the items given, from which replay re-creates the command (so it validates them
again, against the replaying service's scene, exactly as the first time).
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, Self, TypeVar

import numpy as np
from pydantic import ConfigDict

from service.core.commands.base import Announcement, Command, Door
from service.core.commands.fields import example_config
from service.core.errors import BadCommand
from service.core.sim.batch import ModelWrite, StateWrite

__all__ = ["MAX_WRITES", "ManyWrites", "Written", "batch_config"]

MAX_WRITES = 100_000  # writes per command


def batch_config(*writes: dict[str, Any]) -> ConfigDict:
    """The config of a batch body `{"writes": [...]}`: no other field, `writes` its example."""
    return example_config({"writes": list(writes)})


class Written(Protocol):
    """What staging the writes gives back: the tick they take effect at, the worlds written."""

    tick: int
    worlds: list[int]


R = TypeVar("R", bound=Written)


@dataclass(frozen=True)
class ManyWrites(Command[R]):
    """A command made of writes of any worlds (`items`, one a world, as given) that take effect
    together at one tick boundary. A subclass is a frozen dataclass too (any fields of its own
    follow these two), and its `create` validates every item before one write exists."""

    writes: tuple[StateWrite | ModelWrite, ...]
    items: tuple[dict[str, Any], ...]  # as given (validated), for the recording

    @classmethod
    @abstractmethod
    def create(cls, door: Door, items: Sequence[Mapping[str, Any]]) -> Self:
        """The command for `items`, each validated (BadCommand names the first bad field)."""

    @staticmethod
    def counted(items: object, what: str) -> None:
        """Refuse anything but a list of 1..MAX_WRITES items (`what`: what one item writes)."""
        if not isinstance(items, list | tuple) or not 1 <= len(items) <= MAX_WRITES:
            raise BadCommand("writes", f"give 1..{MAX_WRITES} {what} writes")

    @classmethod
    def from_wire(cls, door: Door, world: int, body: dict[str, Any]) -> Self:
        return cls.create(door, [{**body, "world": world}])

    @classmethod
    def from_record(cls, door: Door, rec: dict[str, Any]) -> Self:
        return cls.create(door, rec["writes"])

    def staged(self, door: Door) -> tuple[int, list[int]]:
        """Stage the writes: the tick they take effect at, and the worlds they write."""
        return door.loop.commands.stage_state(self.writes), sorted({w.world for w in self.writes})

    def announce(self, door: Door, result: R) -> Announcement:
        worlds = np.array(result.worlds, dtype=np.int64)
        targets = door.loop.commands.pending_targets(worlds)
        return Announcement(worlds, targets, result.tick, {"writes": list(self.items)})
