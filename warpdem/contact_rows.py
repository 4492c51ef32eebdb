"""Contact rows of a State in the two pair evaluations (``DEMSolver(pair_evaluation=...)``), on the host.

A sphere's row holds its wall contacts first, then its sphere contacts in the order of its
neighbour list (ascending partner index). ``"full"``: both spheres of a pair keep the pair,
each its own view of the history (the partner's spring and rolling history are the negated
vectors). ``"half"``: only the higher-index sphere keeps it. Checkpoints hold full rows in the
sphere-major layout (:meth:`warpdem.solver.DEMSolver.export_state`), whatever the solver's
choices, so a State saved by one solver loads into any other of the same model.

Arrays are those of :meth:`warpdem.model.State.to_numpy` in the sphere-major layout:
``contact_count`` (n,), ``contact_partner`` (n k,), ``contact_spring``/``contact_wnormal``
(n k, 3) and ``contact_roll`` (n k, 3, or one row when the law keeps no rolling history).
"""
from __future__ import annotations

import numpy as np

from .errors import ConfigError

ROW_ARRAYS = ("contact_partner", "contact_spring", "contact_roll", "contact_wnormal")


def _rolling(data: dict, n: int, k: int) -> bool:
    return np.asarray(data["contact_roll"]).shape[0] == n * k


def half_rows_to_full(data: dict[str, np.ndarray], n: int, k: int) -> dict[str, np.ndarray]:
    """Full rows from half rows: each pair (i, j < i) kept by i is added to j's row after j's
    own entries, in ascending i (as a full evaluation writes it), with the negated spring and
    rolling history (the wall normal of a sphere contact is not used: zero). Raises ConfigError
    if a row would need more than ``k`` slots."""
    out = dict(data)
    count = np.asarray(data["contact_count"]).astype(np.int64)
    partner = np.asarray(data["contact_partner"]).reshape(n, k)
    slot = np.arange(k)[None, :]
    pair = (slot < count[:, None]) & (partner >= 0)
    owner, col = np.nonzero(pair)  # owner i (row-major: ascending i), column of the entry
    other = partner[owner, col].astype(np.int64)
    order = np.lexsort((owner, other))  # by partner row, then ascending owner
    owner, col, other = owner[order], col[order], other[order]
    first = np.searchsorted(other, other, side="left")
    position = count[other] + (np.arange(other.size) - first)
    if position.size and position.max() >= k:
        bad = int(other[np.argmax(position)])
        raise ConfigError(f"contact rows: sphere {bad} would need more than {k} contact slots in full rows")
    new_count = count + np.bincount(other, minlength=n)
    out["contact_count"] = new_count.astype(np.asarray(data["contact_count"]).dtype)
    new_partner = partner.copy()
    new_partner[other, position] = owner
    out["contact_partner"] = new_partner.reshape(-1)
    for name, sign in (("contact_spring", -1.0), ("contact_roll", -1.0), ("contact_wnormal", 0.0)):
        if name == "contact_roll" and not _rolling(data, n, k):
            continue
        arr = np.asarray(data[name]).reshape(n, k, 3).copy()
        arr[other, position] = sign * arr[owner, col]
        out[name] = arr.reshape(n * k, 3)
    return out


def full_rows_to_half(data: dict[str, np.ndarray], n: int, k: int) -> dict[str, np.ndarray]:
    """Half rows from full rows: each row keeps its wall entries and its partners of lower index,
    in order (the others' entries are their partners' to keep)."""
    out = dict(data)
    count = np.asarray(data["contact_count"]).astype(np.int64)
    partner = np.asarray(data["contact_partner"]).reshape(n, k)
    slot = np.arange(k)[None, :]
    valid = slot < count[:, None]
    keep = valid & ((partner < 0) | (partner < np.arange(n)[:, None]))
    rows, cols = np.nonzero(keep)
    position = np.cumsum(keep, axis=1)[rows, cols] - 1
    out["contact_count"] = keep.sum(axis=1).astype(np.asarray(data["contact_count"]).dtype)
    for name in ROW_ARRAYS:
        if name == "contact_roll" and not _rolling(data, n, k):
            continue
        arr = np.asarray(data[name])
        shaped = arr.reshape(n, k, *arr.shape[1:])
        new = np.zeros_like(shaped)
        new[rows, position] = shaped[rows, cols]
        out[name] = new.reshape(arr.shape)
    return out


def contacts_per_sphere(count: np.ndarray, partner: np.ndarray, n: int, k: int, rows: str) -> np.ndarray:
    """Each sphere's contacts (walls and spheres) from its row counts (sphere-major ``partner``):
    the counts themselves for full rows; for half rows plus the times it is another row's partner."""
    count = np.asarray(count).astype(np.int64)
    if rows == "full":
        return count
    p = np.asarray(partner).reshape(n, k)
    pair = (np.arange(k)[None, :] < count[:, None]) & (p >= 0)
    return count + np.bincount(p[pair], minlength=n)
