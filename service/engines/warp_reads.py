"""How a WorldBatch's state leaves the device: snapshots and packed frame rows (mixed in).

Apart from warp.py because it is the part of the engine that the loop's publishing and the
streams lean on: a snapshot through pinned buffers (`snapshot`), the same with its copy to the
host made beside the next tick (`snapshot_beside`, the loop's periodic snapshot that nobody
waits for), and the rows of chosen worlds packed on the device (`pack_rows`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import warp as wp

from service.core.sim.packed_rows import PackedRows
from service.core.sim.types import Snapshot
from service.engines.warp_frames import BesideCopy, DevicePacker, PinnedPool
from service.engines.warp_snapshot import SnapshotArrays, snapshot_from


class DeviceReads:
    """Reading a WorldBatch's gathered state (the batch's own attributes, set at build)."""

    device: wp.Device
    tick_dt: float
    copies_beside: bool  # snapshot_beside copies beside the next tick (CUDA), else None
    _tick: int
    _world_ticks: np.ndarray
    _faults: np.ndarray
    _targets: np.ndarray
    _state: wp.array  # (nworld, NCOL) gathered at the end of every tick
    _bodies: wp.array  # (nworld, nbody, 7)
    _targets_dev: wp.array
    _wticks: wp.array
    _faults_dev: wp.array
    _pinned: PinnedPool
    _beside: BesideCopy
    _packer: DevicePacker

    def snapshot(self) -> Snapshot:
        """All worlds at the end of the last completed tick, copied to host memory."""
        return snapshot_from(self.snapshot_arrays(), self._targets.copy())

    def snapshot_arrays(self) -> SnapshotArrays:
        """The snapshot as the few contiguous host arrays it is made of (cheap to ship: Ray).

        On a GPU they are views of pinned buffers, reused once no reader holds them: one copy
        and no allocation per snapshot. On the CPU .numpy() is a view the next tick overwrites.
        """
        if self.device.is_cuda:
            state, bodies = self._pinned.copy_out((self._state, self._bodies), self.device)
        else:
            state, bodies = self._state.numpy().copy(), self._bodies.numpy().copy()
        return self._arrays(state, bodies)

    def snapshot_beside(self) -> tuple[Snapshot, Callable[[], None]] | None:
        """batch.SnapshotsBeside: `snapshot`, its arrays filled beside the next tick
        (warp_frames.BesideCopy), valid once the wait returned; None unless `copies_beside`
        (on the CPU the copy is all a snapshot costs: nothing to overlap)."""
        if not self.copies_beside:
            return None
        (state, bodies), wait = self._beside.start((self._state, self._bodies))
        return snapshot_from(self._arrays(state, bodies), self._targets.copy()), wait

    def _arrays(self, state: np.ndarray, bodies: np.ndarray) -> SnapshotArrays:
        """The host side of a snapshot of this tick around its state and bodies."""
        return SnapshotArrays(
            self._tick, self._world_ticks * self.tick_dt, state, bodies, self._faults.copy()
        )

    def pack_rows(self, ids: np.ndarray) -> PackedRows | None:
        """The frame rows of worlds `ids` at the last tick, gathered and copied on the device
        (service.device_frames); None when that selection's buffers are all in flight."""
        return self._packer.pack(
            self._tick, ids, self._state, self._targets_dev, self._wticks, self._faults_dev
        )
