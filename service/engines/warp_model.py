"""Per-world Model fields on MuJoCo Warp: a shared field made batched, and rows written to it.

mujoco_warp's kernels read a Model field of leading size 1 as shared by every world and one of
leading size nworld per world (`field[worldid % field.shape[0]]`), as `put_model(mjm,
batch_sizes={field: nworld})` builds it: so only the fields some world changed pay for a row
per world, in memory and in reads. Except on a CPU, where the fields a parameter may write
(`writable_fields`) are per world from the build: making one so later captures the tick again,
which takes seconds there, on the sim thread (WorldBatch's constructor says why that matters).
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import mujoco_warp as mjw
import numpy as np
import warp as wp

from service.core.commands.params import param_table

# What mjw.set_const writes per world that depends on the fields a command may write (masses,
# inertia, armature): made batched before it runs.
DERIVED = ("body_subtreemass", "body_invweight0", "dof_invweight0", "actuator_acc0")


def writable_fields(mjm: mujoco.MjModel, commanded: Sequence[str]) -> tuple[str, ...]:
    """Every Model field a parameter write may change (service/core/commands/params.py's
    table of this model), and what mjw.set_const derives from them."""
    fields = {f for p in param_table(mjm, commanded).values() for f in p.fields}
    return (*sorted(fields), *DERIVED)


def host_layout(arr: wp.array) -> tuple[tuple[int, ...], type]:
    """(shape, numpy dtype) of `arr.numpy()` without copying a device array to find out."""
    scalar = getattr(arr.dtype, "_wp_scalar_type_", arr.dtype)
    inner = tuple(getattr(arr.dtype, "_shape_", ()))
    return (*arr.shape, *inner), wp.dtype_to_numpy(scalar)


def batched(m: mjw.Model, field: str, nworld: int, device: wp.context.Device) -> bool:
    """Give `field` one row per world (copies of its shared row); True if it was shared."""
    array = getattr(m, field)
    if array.shape[0] == nworld:
        return False
    host = np.repeat(array.numpy(), nworld, axis=0)
    setattr(m, field, wp.array(host, dtype=array.dtype, device=device))
    return True


def write_rows(array: wp.array, worlds: np.ndarray, rows: np.ndarray, on_cpu: bool) -> None:
    """Rows (k, ...) of a batched field for `worlds`, in the array's own dtype and layout."""
    shape, dtype = host_layout(array)
    rows = rows.astype(dtype).reshape(len(worlds), *shape[1:])
    if on_cpu:
        array.numpy()[worlds] = rows  # a view of the same memory
        return
    host = array.numpy()
    host[worlds] = rows
    array.assign(host)
