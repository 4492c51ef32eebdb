"""Where entry ``k`` of sphere ``i`` lies in a per-sphere slot array (the Verlet list, the
contact history and the wall slots): one ``wp.func`` per layout, chosen when a kernel is built.

``"sphere_major"`` (default): a sphere's entries are contiguous, entry ``i * per_row + k``.
``"slot_major"``: entry ``k`` of all spheres is contiguous, entry ``k * rows + i``, so the
threads of a warp (consecutive spheres) reading their k-th entries read consecutive addresses
(one coalesced load instead of one per thread). ``rows`` is the number of spheres; ``per_row``
the slots per sphere. Both layouts hold the same values; only their order in memory differs, so
results are bit for bit the same. Host code that reads the arrays as (rows, per_row) goes
through :func:`to_sphere_major` / :func:`from_sphere_major`.
"""
from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False, "fast_math": True})

SLOT_LAYOUTS = ("sphere_major", "slot_major")
DEFAULT_SLOT_LAYOUT = "sphere_major"


@wp.func
def sphere_major_entry(i: int, k: int, rows: int, per_row: int) -> int:
    """Entry k of sphere i, a sphere's entries contiguous."""
    return i * per_row + k


@wp.func
def slot_major_entry(i: int, k: int, rows: int, per_row: int) -> int:
    """Entry k of sphere i, the k-th entries of all spheres contiguous."""
    return k * rows + i


def entry_function(layout: str) -> "wp.Function":
    """The ``wp.func`` (i, k, rows, per_row) -> flat index of ``layout``, compiled into the
    kernels that read or write the arrays (so the default costs nothing at run time)."""
    functions = {"sphere_major": sphere_major_entry, "slot_major": slot_major_entry}
    if layout not in functions:
        raise ValueError(f"unknown slot layout {layout!r}; valid: {list(functions)}")
    return functions[layout]


def to_sphere_major(values: np.ndarray, layout: str, rows: int, per_row: int) -> np.ndarray:
    """A flat slot array (``rows * per_row`` entries, trailing dimensions kept) of ``layout`` in
    the default layout (a copy). Arrays of another length (the 1-entry rolling history of a law
    that keeps none) are returned unchanged."""
    a = np.asarray(values)
    entry_function(layout)  # validates the name
    if layout == "sphere_major" or a.shape[0] != rows * per_row:
        return a.copy()
    return np.ascontiguousarray(a.reshape((per_row, rows) + a.shape[1:]).swapaxes(0, 1)).reshape(a.shape)


def from_sphere_major(values: np.ndarray, layout: str, rows: int, per_row: int) -> np.ndarray:
    """The inverse of :func:`to_sphere_major`: a default-layout flat slot array in ``layout``."""
    a = np.asarray(values)
    entry_function(layout)
    if layout == "sphere_major" or a.shape[0] != rows * per_row:
        return a.copy()
    return np.ascontiguousarray(a.reshape((rows, per_row) + a.shape[1:]).swapaxes(0, 1)).reshape(a.shape)
